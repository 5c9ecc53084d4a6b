"""Reading a log of plain numbers with numpy, so that a command need not import pandas.

Most logs are what a rig or pmdcid itself writes: ``#`` comments, a comma-separated header,
then rows of plain numbers. :func:`read_plain` parses such a file with :func:`numpy.loadtxt`
(pandas' import is ~0.3 s of a command that takes a second). It accepts a file only when the
data rows hold nothing but digits, signs, points, exponents, commas and newlines, and returns
None for anything else (quotes, spaces, empty or text cells, ``nan``, a byte-order mark, another
separator, a ragged row), and for any file where pandas could give other numbers: pandas is
then the reader, with its messages, exactly as before. On the files it accepts the two give the
same bits (``tests/io/test_plain.py``: fixtures and random numbers in many formats).
"""

from __future__ import annotations

import io as _io
import os

import numpy as np

#: files up to this size take the numpy path; larger ones pandas, whose parser is ~3x faster per
#: row than np.loadtxt (above ~15 MB the pandas import pays for itself)
MAX_BYTES = 16 << 20
#: the only bytes accepted in the data rows
_PLAIN = b"0123456789+-.eE,\r\n"


class PlainFrame:
    """The few parts of a DataFrame that :func:`pmdcid.io.build.frame_columns` uses: ``columns``,
    ``len()`` and ``frame[name]`` (a float64 column). ``values``: a 2-D array (a row per
    sample) or a list of 1-D arrays, one per column (:mod:`pmdcid.io.chunked`)."""

    def __init__(self, columns: list[str], values: np.ndarray | list[np.ndarray]):
        self._values = values
        self.columns = columns

    @property
    def columns(self) -> list[str]:
        return self._columns

    @columns.setter
    def columns(self, names: list[str]) -> None:
        self._columns = list(names)
        self._index = {c: j for j, c in enumerate(self._columns)}

    def __len__(self) -> int:
        return len(self._values[0]) if isinstance(self._values, list) else self._values.shape[0]

    def __getitem__(self, name: str) -> np.ndarray:
        if isinstance(self._values, list):
            return self._values[self._index[name]]
        return self._values[:, self._index[name]]

    def head(self, n: int) -> PlainFrame:
        """The first ``n`` rows (as ``DataFrame.head``)."""
        if isinstance(self._values, list):
            return PlainFrame(self._columns, [v[:n] for v in self._values])
        return PlainFrame(self._columns, self._values[:n])


def read_plain(path: str, nskip: int) -> PlainFrame | None:
    """The data rows of ``path`` after ``nskip`` comment lines and the header, or None when the
    file is not plain numbers under a plain header (then pandas reads it)."""
    try:
        if os.path.getsize(path) > MAX_BYTES:
            return None
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError:
        return None
    pos = 0
    for _ in range(nskip):
        pos = data.find(b"\n", pos) + 1
        if pos == 0:
            return None
    try:  # the skipped lines must be lines by str.splitlines too (as the comment reader counts)
        prefix = data[:pos].decode("utf-8").splitlines(keepends=True)
    except UnicodeDecodeError:
        return None
    if data.startswith(b"\xef\xbb\xbf") or len(prefix) != nskip or any(
            not ln.endswith("\n") for ln in prefix):
        return None
    end = data.find(b"\n", pos)
    if end < 0:
        return None
    header, body = data[pos:end].removesuffix(b"\r"), data[end + 1:]
    if not header.isascii() or any(b in header for b in (b'"', b"\r", b"\t", b";")):
        return None
    cols = [c.strip() for c in header.decode("ascii").split(",")]  # as pandas names them
    if not all(cols):
        return None
    if not body.strip() or body.translate(None, _PLAIN):
        return None
    if body.count(b"\r") != body.count(b"\r\n"):
        return None
    try:
        values = np.loadtxt(_io.BytesIO(body), delimiter=",", dtype=float, ndmin=2,
                            comments=None)
    except (ValueError, IndexError):  # ragged rows, empty cells, '1e', '--1': pandas says why
        return None
    if values.shape[1] != len(cols) or not _same_as_pandas(values):
        return None
    return PlainFrame(cols, values)


def _same_as_pandas(values: np.ndarray) -> bool:
    """False when pandas might give other numbers: a non-finite value, or, in a column it would
    read as integers (every value integral), a negative zero (its int64 makes it +0) or an
    integer beyond 2**53."""
    if values.size == 0 or not np.isfinite(values).all():
        return False
    for j in range(values.shape[1]):
        col = values[:, j]
        if np.all(col == np.trunc(col)) and (np.any((col == 0) & np.signbit(col))
                                              or np.abs(col).max() >= 2.0**53):
            return False
    return True


__all__ = ["MAX_BYTES", "PlainFrame", "read_plain"]
