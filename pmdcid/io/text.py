"""Reading small text files (model, mapping, summary) as editors and rigs save them.

A UTF-8 byte-order mark (Windows Notepad, Excel) is dropped; a UTF-16 file with its BOM is
decoded as UTF-16. Anything else must be UTF-8 (:class:`UnicodeDecodeError` otherwise).
"""

from __future__ import annotations

import codecs
import os

BOMS_16 = (codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)


def decode(data: bytes) -> str:
    """Text of ``data``: UTF-16 when it starts with a UTF-16 BOM, else UTF-8 (BOM dropped)."""
    if data.startswith(codecs.BOM_UTF8):
        return data[len(codecs.BOM_UTF8):].decode("utf-8")
    if data.startswith(BOMS_16):
        text = data.decode("utf-16")
        if sum(c.isascii() for c in text) < 0.9 * len(text):  # BOM-like bytes, then garbage
            raise UnicodeDecodeError("utf-16", data, 0, 2, "not UTF-16 text")
        return text
    return data.decode("utf-8")


def read_text(path: str | os.PathLike) -> str:
    """The file's text (see :func:`decode`), read once (a pipe works too)."""
    with open(path, "rb") as fh:
        return decode(fh.read())
