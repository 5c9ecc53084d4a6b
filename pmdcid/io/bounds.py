"""Resource bounds of a log, checked before the work and naming the file.

- :func:`check_lines`: no line of a log is longer than :data:`MAX_LINE_BYTES` (a row of numbers
  never is; a 50 MB single line is an export gone wrong, which would take a minute and gigabytes
  to parse before failing). One pass over the bytes, in chunks: a regular file is scanned
  without being held in memory, and the scan stops at the first line past the bound.
- :data:`MAX_DIAGNOSE_ROWS` (used by :mod:`pmdcid.diagnose.files`): the most rows diagnose's
  refits take from one log; longer logs are refused with the way to proceed.
"""

from __future__ import annotations

import io
import math

import numpy as np

from pmdcid.errors import LogError

#: longest line a log may have [bytes] (a transposed export of 120 000 columns is ~1 MB)
MAX_LINE_BYTES = 4 << 20
#: bytes scanned at a time
SCAN_CHUNK = 8 << 20
#: most rows (all logs together) diagnose takes: past it its refits take minutes and gigabytes
#: (5 million rows: 6.5 min, 4.5 GB)
MAX_DIAGNOSE_ROWS = 2_000_000


def _too_long(line: int, length: int, p: str):
    return LogError(f"line {line} is longer than {MAX_LINE_BYTES >> 20} MB ({length / 2**20:.0f}"
                    " MB or more): a log has one row of numbers per line; check how it was "
                    "exported (one row per sample, a newline after each)", p)


def check_lines(handle, p: str) -> None:
    """Raise :class:`LogError` naming ``p`` when a line of ``handle`` (a path, or the in-memory
    bytes of a pipe) is longer than :data:`MAX_LINE_BYTES`."""
    if isinstance(handle, io.BytesIO):
        return _scan(io.BytesIO(handle.getbuffer()), p)
    if isinstance(handle, str):
        with open(handle, "rb") as fh:
            return _scan(fh, p)
    return None


def _scan(fh, p: str) -> None:
    """Lines end at LF or CR (a CR-only export too); line numbers count LFs (CRLF: one line)."""
    start = pos = 0  # where the current line starts, bytes read so far
    newlines = 0  # LFs before this chunk
    while True:
        chunk = fh.read(SCAN_CHUNK)
        if not chunk:
            break
        b = np.frombuffer(chunk, np.uint8)
        lf = b == 10
        ends = np.flatnonzero(lf | (b == 13)) + pos
        if ends.size:
            gaps = np.diff(ends, prepend=start - 1) - 1
            worst = int(np.argmax(gaps))
            if gaps[worst] > MAX_LINE_BYTES:
                begin = max(int(ends[worst] - gaps[worst]) - pos, 0)
                raise _too_long(newlines + int(np.count_nonzero(lf[:begin])) + 1,
                                int(gaps[worst]), p)
            start = int(ends[-1]) + 1
        newlines += int(np.count_nonzero(lf))
        pos += len(chunk)
        if pos - start > MAX_LINE_BYTES:
            raise _too_long(newlines + 1, pos - start, p)
    return None


def check_rows(logs, limit: int, command: str) -> None:
    """Refuse (one line naming the longest log) more than ``limit`` rows in all, saying how to
    proceed: keep every k-th row, or a part of the logs."""
    n = sum(lg.n for lg in logs)
    if n <= limit:
        return
    longest = max(logs, key=lambda lg: lg.n)
    k = math.ceil(n / limit)
    raise LogError(f"{command} takes at most {limit:,} rows in all and the logs hold {n:,}: "
                   f"keep one row in {k} (or a part of each log) and rerun; fit-nonlinear "
                   "and simulate take any length", str(longest.path))
