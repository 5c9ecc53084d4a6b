"""Reading a large log in chunks of rows, so that its peak memory stays near its numbers' size.

A log over :data:`pmdcid.io.plain.MAX_BYTES` goes to pandas (its parser is ~3x faster per row
than ``numpy.loadtxt``). Read whole, pandas holds its parser's buffers and the whole frame, and
the columns are copied out of it: a 100 MB, 2-million-row log took ~430 MB of resident memory
to read (docs/performance.md). :func:`read_chunked` reads it ``CHUNK_ROWS`` rows at a time with
the same parser and options as the whole-file read, every column as float64, and joins the
columns one at a time: the same numbers, bit for bit, as the whole-file read gives
(``tests/io/test_chunked.py``), in about the size of the numbers plus one column.

It steps aside (returns None, and the whole-file read serves, with its messages) for anything
where the two could differ: a cell that is not a number (text, booleans), a parse error, or a
column pandas would read as integers (every value integral) holding a negative zero (its int64
makes it +0) or an integer beyond 2**53.
"""

from __future__ import annotations

import numpy as np

from pmdcid.io.plain import MAX_BYTES, PlainFrame

#: files larger than this are read in chunks (smaller ones whole: numpy's or pandas' reader)
CHUNKED_BYTES = MAX_BYTES
#: rows per chunk (five columns: 5 MB of numbers per chunk)
CHUNK_ROWS = 1 << 17


def read_chunked(src, nskip: int, chunk_rows: int | None = None) -> PlainFrame | None:
    """The data rows of ``src`` (a :class:`pmdcid.io.csvsource.Source` on a path) as a
    :class:`PlainFrame` of float64 columns, or None when the whole-file read must serve."""
    import pandas as pd

    cols: list[np.ndarray] = []
    n = 0
    try:
        reader = pd.read_csv(src.handle, skiprows=nskip, skipinitialspace=True,
                             encoding="utf-8-sig", encoding_errors="replace", sep=src.sep,
                             decimal=src.decimal, dtype=float,
                             chunksize=chunk_rows or CHUNK_ROWS)
        with reader:
            for chunk in reader:
                if not cols:
                    names = [str(c) for c in chunk.columns]
                    cols = [np.empty(_rows_estimate(src, nskip)) for _ in names]
                k = len(chunk)
                if n + k > len(cols[0]):  # more rows than estimated: grow (amortised)
                    for c in cols:
                        c.resize(max(n + k, len(c) * 3 // 2), refcheck=False)
                block = chunk.to_numpy(dtype=float)
                for j, c in enumerate(cols):
                    c[n:n + k] = block[:, j]
                n += k
    except (ValueError, TypeError, pd.errors.ParserError, pd.errors.EmptyDataError,
            UnicodeDecodeError):
        return None  # the whole-file read says what is wrong, as before
    if not cols or n == 0:
        return None
    for c in cols:
        c.resize(n, refcheck=False)  # in place (realloc): no copy of the numbers
        if not _same_as_whole(c):
            return None
    return PlainFrame(names, cols)


def _rows_estimate(src, nskip: int) -> int:
    """Data rows of the file, estimated from its size and the mean length of the rows in its
    head (a little over, so that the columns rarely grow)."""
    import os

    lines = src.head.splitlines(keepends=True)[nskip + 1:-1] or [" " * 16]
    per_row = max(1.0, sum(len(ln.encode()) for ln in lines) / len(lines))
    return int(os.path.getsize(src.handle) / per_row * 1.05) + 1024


def _same_as_whole(col: np.ndarray) -> bool:
    """False when the whole-file read might give other numbers: in a column it reads as
    integers (every value integral, none missing), a negative zero or an integer beyond 2**53."""
    if len(col) == 0 or not np.isfinite(col).all() or not np.all(col == np.trunc(col)):
        return True
    return not (np.any((col == 0) & np.signbit(col)) or np.abs(col).max() >= 2.0**53)


__all__ = ["CHUNKED_BYTES", "CHUNK_ROWS", "read_chunked"]
