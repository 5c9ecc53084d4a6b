"""Resource bounds of a log, checked before the work and naming the file.

- :func:`check_lines`: no line of a log is longer than :data:`MAX_LINE_BYTES` (a row of numbers
  never is; a 50 MB single line is an export gone wrong, which would take a minute and gigabytes
  to parse before failing). A quick pass reads a few kB of every 2 MB (0.4 ms for 40 MB); only
  when a block holds no line end, an exact pass in chunks finds the line (it stops there).
- :data:`MAX_DIAGNOSE_ROWS` (used by :mod:`pmdcid.diagnose.loop`): the most rows diagnose's
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
#: bytes read at a time by the quick pass
PEEK = 1 << 16
#: most rows (all logs together) diagnose takes: past it its refits take minutes and gigabytes
#: (5 million rows: 6.5 min, 4.5 GB)
MAX_DIAGNOSE_ROWS = 2_000_000


def _too_long(line: int, length: int, p: str):
    return LogError(f"line {line} is longer than {MAX_LINE_BYTES >> 20} MB ({length / 2**20:.0f}"
                    " MB or more): a log has one row of numbers per line; check how it was "
                    "exported (one row per sample, a newline after each)", p)


def check_lines(handle, p: str) -> None:
    """Raise :class:`LogError` naming ``p`` when a line of ``handle`` (a path, or the in-memory
    bytes of a pipe) is longer than :data:`MAX_LINE_BYTES`. A quick pass first (every aligned
    block of half the bound must hold a line end: memchr speed, a line past the bound covers a
    whole block), the exact scan (which line) only when a block holds none."""
    if isinstance(handle, io.BytesIO):
        def reopen():
            return io.BytesIO(handle.getbuffer())
    elif isinstance(handle, str):
        def reopen():
            return open(handle, "rb")
    else:
        return None
    with reopen() as fh:
        if _every_block_ends_a_line(fh):
            return None
    with reopen() as fh:
        return _scan(fh, p)


def _every_block_ends_a_line(fh) -> bool:
    """Whether every aligned block of ``MAX_LINE_BYTES // 2`` bytes holds a line end; each
    block is read from its start only until one is found (a few kB for a log)."""
    half = MAX_LINE_BYTES // 2
    head = fh.read(PEEK)
    term = b"\r" if b"\n" not in head and b"\r" in head else b"\n"
    block = 0
    while True:
        fh.seek(block)
        seen = 0
        while seen < half:
            part = fh.read(min(PEEK, half - seen))
            if not part:
                return True  # the file ends inside this block: no whole block left
            if term in part:
                break
            seen += len(part)
        else:
            return False
        block += half


def _scan(fh, p: str) -> None:
    """Lines end at LF (CRLF too), or at CR in a file whose first chunk holds CR but no LF (an
    old Mac export); one comparison per byte."""
    start = pos = 0  # where the current line starts, bytes read so far
    lines = 0  # line ends before this chunk
    term = None
    while True:
        chunk = fh.read(SCAN_CHUNK)
        if not chunk:
            break
        if term is None:
            term = 13 if b"\n" not in chunk and b"\r" in chunk else 10
        ends = np.flatnonzero(np.frombuffer(chunk, np.uint8) == term) + pos
        if ends.size:
            gaps = np.diff(ends, prepend=start - 1) - 1
            worst = int(np.argmax(gaps))
            if gaps[worst] > MAX_LINE_BYTES:
                raise _too_long(lines + worst + 1, int(gaps[worst]), p)
            start = int(ends[-1]) + 1
            lines += ends.size
        pos += len(chunk)
        if pos - start > MAX_LINE_BYTES:
            raise _too_long(lines + 1, pos - start, p)
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
