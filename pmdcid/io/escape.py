"""User text into another language: one rule per output language, in this one place.

A string that comes from the user -- a file or folder name, a column, an effect or a parameter
name, a unit -- may hold quotes, backslashes, newlines, terminal escape sequences, ``$`` or
anything else. Every piece of generated code, every figure label and every line printed to a
terminal passes such text through the function for its language here; numbers go through
:func:`number` (NaN refused, infinity spelled as the language spells it).

Rules (each function returns text that the language reads back as the user's text, shown
visibly; nothing the user wrote is ever executed, parsed as markup or sent to the terminal as a
control sequence):

- :func:`visible`: characters that are not printable (controls, ESC, DEL, C1, bidi overrides,
  line and paragraph separators, lone surrogates from undecodable file names) as ``\\xNN``,
  ``\\uNNNN`` or ``\\UNNNNNNNN``, and a backslash doubled; the base of the other rules.
- :func:`py_str` / :func:`py_text`: a Python string literal / the inside of a ``\"\"\"...\"\"\"``
  docstring (ASCII only, quotes and backslashes escaped: never closes the literal).
- :func:`c_str` / :func:`c_comment`: a C string literal (octal escapes of the UTF-8 bytes,
  ``?`` escaped against trigraphs) / the text of a ``/* ... */`` comment (``*/`` broken).
- :func:`c_include`: a name for ``#include "..."``, where C has no escapes: letters, digits,
  ``_ . + -`` only, anything else refused (:class:`UnsafeTextError`).
- :func:`m_str` / :func:`m_comment`: a MATLAB/Octave char array ``'...'`` / the text of a ``%``
  comment (one line: a newline in a name never starts a live line).
- :func:`xml_text`: XML/HTML text and attribute values (``& < > " '`` as entities; characters XML
  1.0 cannot hold shown visibly). The report's HTML keeps ``html.escape``; this is the same rule
  for exporters that write XML (MuJoCo, FMI's modelDescription).
- :func:`terminal`: a line for the terminal (newlines and tabs kept when ``keep_newlines``).
- :func:`mpl_text`: matplotlib text: ``$`` escaped so user text is never parsed as mathtext.
- :func:`number`: a float literal that reads back exactly; NaN refused, infinity as ``inf``.
"""

from __future__ import annotations

import math
import re

from pmdcid.errors import PmdcidError


class UnsafeTextError(PmdcidError):
    """A user's text cannot be written in the output language (e.g. a quote in a C header name),
    or a number is not finite where the output needs one."""


def _escape_char(ch: str) -> str:
    o = ord(ch)
    if o < 0x100:
        return f"\\x{o:02x}"
    if o < 0x10000:
        return f"\\u{o:04x}"
    return f"\\U{o:08x}"


def visible(text: str, keep: str = "") -> str:
    """``text`` with every non-printable character (except those in ``keep``) as an escape and
    backslashes doubled: what the user wrote, shown, never acted on."""
    out = []
    for ch in str(text):
        if ch == "\\":
            out.append("\\\\")
        elif ch.isprintable() or ch in keep:
            out.append(ch)
        else:
            out.append(_escape_char(ch))
    return "".join(out)


def py_text(text: str) -> str:
    """The inside of a Python string literal (any quotes): ASCII, reads back as ``text``."""
    out = []
    for ch in str(text):
        if ch in "\\\"'":
            out.append("\\" + ch)
        elif " " <= ch <= "~":
            out.append(ch)
        else:
            out.append(_escape_char(ch))
    return "".join(out)


def py_str(text: str) -> str:
    """A Python string literal whose value is ``text``."""
    return '"' + py_text(text) + '"'


def c_str(text: str) -> str:
    """A C string literal whose bytes are ``text`` in UTF-8."""
    out = []
    for b in str(text).encode("utf-8", "surrogateescape"):
        ch = chr(b)
        if ch in "\\\"?":
            out.append("\\" + ch)
        elif 0x20 <= b < 0x7F:
            out.append(ch)
        else:
            out.append(f"\\{b:03o}")
    return '"' + "".join(out) + '"'


def c_comment(text: str) -> str:
    """Text for inside a ``/* ... */`` comment: one ASCII line, ``*/`` and ``/*`` broken, no
    trailing backslash (no trigraph or line splice either)."""
    s = py_text(text).replace('\\"', '"').replace("\\'", "'")
    return s.replace("*/", "* /").replace("/*", "/ *").replace("??", "?\\?")


_INCLUDE = re.compile(r"[A-Za-z0-9_][A-Za-z0-9_.+\-]{0,200}")


def c_include(name: str, path: str | None = None) -> str:
    """``name`` for ``#include "name"`` (C has no escapes there): refused unless it is made of
    letters, digits, ``_``, ``.``, ``+`` and ``-``."""
    if not _INCLUDE.fullmatch(str(name)):
        raise UnsafeTextError(f"C file name {visible(name)[:60]!r} can not be #included: use "
                              "letters, digits, _ . + - only (e.g. -o motor.c)", path)
    return str(name)


def m_str(text: str) -> str:
    """A MATLAB/Octave char array literal ``'...'`` whose text is ``visible(text)``."""
    return "'" + visible(text).replace("'", "''") + "'"


def m_comment(text: str) -> str:
    """Text for a ``%`` comment line: one line, control characters shown as escapes."""
    return visible(text)


def xml_text(text: str) -> str:
    """XML/HTML text or attribute value (quotes too); characters XML 1.0 cannot hold shown as
    escapes."""
    s = visible(text)
    return (s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;").replace("'", "&#x27;"))


def terminal(text: str, keep_newlines: bool = False) -> str:
    """``text`` safe to print on a terminal: no escape or control sequence reaches it (ESC, CR,
    BEL, backspace, C1, bidi overrides shown as ``\\x1b``...). ``keep_newlines`` keeps ``\\n``
    and ``\\t`` (tables)."""
    s = str(text)
    if s.isprintable():
        return s
    keep = "\n\t" if keep_newlines else ""
    out = []
    for ch in s:
        out.append(ch if ch.isprintable() or ch in keep else _escape_char(ch))
    return "".join(out)


def mpl_text(text: str) -> str:
    """Text for a matplotlib label or title: never parsed as mathtext (``$`` escaped), one line,
    control characters shown as escapes."""
    return visible(text).replace("$", r"\$")


def number(x: float, inf: str = "inf", nan: str | None = None, what: str = "value") -> str:
    """A float literal that reads back exactly (17 significant digits); ``inf`` spells infinity
    (``"math.inf"``, ``"INFINITY"``, ``"Inf"``). NaN is refused (:class:`UnsafeTextError`)
    unless the language spells it (``nan``)."""
    try:
        x = float(x)
    except (TypeError, ValueError, OverflowError):
        raise UnsafeTextError(f"{what} is not a number ({visible(repr(x))[:30]})") from None
    if math.isnan(x):
        if nan is None:
            raise UnsafeTextError(f"{what} is NaN: the generated code needs a number; fix the "
                                  "model (rerun the stage that identifies it)")
        return nan
    if math.isinf(x):
        return inf if x > 0 else "-" + inf
    return repr(x)


__all__ = ["UnsafeTextError", "c_comment", "c_include", "c_str", "m_comment", "m_str",
           "mpl_text", "number", "py_str", "py_text", "terminal", "visible", "xml_text"]
