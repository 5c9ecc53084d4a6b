"""LabVIEW TDMS logs (``.tdms``) through nptdms: series named ``group/channel``.

A channel's instants come from its waveform properties (``wf_increment``, ``wf_start_offset``
in the unit of ``wf_xunit_string``, ``wf_start_time``: channels started at different absolute
times are aligned) or, without them, from its group's time channel (one named ``t``, ``time``,
``Time``, ``timestamp`` or a timestamp-typed channel, in its ``unit_string``: the group is then a
table). The unit is the ``unit_string`` property.

A TDMS file is a run of segments, each with a lead-in giving its length. nptdms reads a file cut
short within its last segment to the end of what is there, channels of unequal lengths, with
log lines of its own. :func:`segments` walks the lead-ins instead: a file cut short is read up
to the end of its last whole segment with one warning saying how much was kept, or refused in
one line when no whole segment holds data. A segment whose length LabVIEW never wrote (the
writer stopped before closing the file) is read to the end of the file, and that is said too.
"""

from __future__ import annotations

import io
import logging
from contextlib import contextmanager

import numpy as np

from pmdcid.errors import LogError, warn
from pmdcid.io.formats import Series, Signals, byte_count, need

EXTENSIONS = (".tdms",)
EXTRA = "tdms"
TIME_NAMES = ("t", "time", "Time", "timestamp", "Timestamp", "timestamps")
#: a time that looks like ms, us or ns (:func:`pmdcid.io.formats.own_time_fix`)
TIME_UNIT_FIX = ("write wf_xunit_string '{unit}' on its channels (unit_string on a time channel), "
                 "which pmdcid reads")


def _seconds(x: np.ndarray) -> np.ndarray:
    """Numbers as they are; datetimes as seconds [s] since 1970."""
    x = np.asarray(x)
    if x.dtype.kind == "M":
        return x.astype("datetime64[ns]").astype(np.int64).astype(float) * 1e-9
    return x.astype(float)


def _time_factor(unit) -> float:
    """Seconds per unit of a time unit the file names (``ms``, ``us``, ``ns``, ``s``); 1 for
    none."""
    from pmdcid.io.headers import UNIT_TABLE

    table = {**UNIT_TABLE, "ns": (1e-9, "time")}
    factor, dim = table.get(str(unit or "s").replace(" ", ""), (1.0, "time"))
    return factor if dim == "time" else 1.0


def _group_time(group) -> tuple[str | None, np.ndarray | None]:
    """The group's time channel [s]: numbers in its ``unit_string`` (s when none), datetimes."""
    for ch in group.channels():
        if ch.name in TIME_NAMES or np.asarray(ch[:]).dtype.kind == "M":
            return ch.name, _seconds(ch[:]) * _time_factor(ch.properties.get("unit_string"))
    return None, None


def _wave_time(ch) -> np.ndarray | None:
    """A waveform channel's instants [s]: ``wf_increment`` and ``wf_start_offset`` are in its
    ``wf_xunit_string`` (s when none; LabVIEW writes ms for a chart in ms)."""
    if "wf_increment" not in ch.properties:
        return None
    try:
        t = np.asarray(ch.time_track(), dtype=float)
    except (KeyError, ValueError):
        return None
    return t * _time_factor(ch.properties.get("wf_xunit_string"))


def _start(ch) -> float | None:
    st = ch.properties.get("wf_start_time")
    if st is None:
        return None
    return float(_seconds(np.asarray([st]))[0])


LEAD_IN = 28  # "TDSm", table-of-contents mask, version, next segment offset, raw data offset
UNWRITTEN = 0xFFFFFFFFFFFFFFFF  # a next segment offset LabVIEW never wrote


def segments(fh, size: int) -> tuple[int, int, int, bool]:
    """(end of the last whole segment [byte], whole segments, bytes the cut one lacks: 0 when
    the file ends on a segment's end, True when the last segment's length was never written)
    of an open TDMS file of ``size`` bytes. A lead-in that is not one stops the walk (nptdms
    says what is wrong with it)."""
    pos, count = 0, 0
    while pos < size:
        fh.seek(pos)
        lead = fh.read(LEAD_IN)
        if len(lead) >= 4 and lead[:4] != b"TDSm":
            return size, count, 0, False
        if len(lead) < LEAD_IN:
            return pos, count, LEAD_IN - len(lead), False
        order = "big" if int.from_bytes(lead[4:8], "little") & (1 << 6) else "little"
        nxt = int.from_bytes(lead[12:20], order)
        if nxt == UNWRITTEN:
            return size, count, 0, True
        end = pos + LEAD_IN + nxt
        if end > size:
            return pos, count, end - size, False
        pos, count = end, count + 1
    return pos, count, 0, False


@contextmanager
def _quiet():
    """nptdms's own log lines (it prints them on stderr) held back: the reader says it once."""
    loggers = [lg for name, lg in logging.Logger.manager.loggerDict.items()
               if name.startswith("nptdms") and isinstance(lg, logging.Logger)]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.ERROR)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels, strict=True):
            lg.setLevel(level)


def _open(nptdms, path: str):
    """The read TdmsFile; a file cut short read to its last whole segment, with a warning."""
    try:
        with open(path, "rb") as fh:
            size = fh.seek(0, 2)
            end, count, missing, unwritten = segments(fh, size)
            if missing:
                if count == 0:
                    raise LogError(f"the TDMS file is cut short ({byte_count(missing)} of its "
                                   "first segment missing): it was not closed properly and "
                                   "holds no whole segment", path)
                fh.seek(0)
                whole = io.BytesIO(fh.read(end))
        with _quiet():
            f = nptdms.TdmsFile.read(whole if missing else path)
    except (ValueError, OSError, KeyError, EOFError) as exc:
        raise LogError(f"is not a readable TDMS file ({str(exc)[:100]})", path) from None
    if missing:
        warn(f"the TDMS file is cut short ({byte_count(missing)} of a segment missing): it was "
             f"not closed properly; read its {count} whole segments ({end} of {size} bytes), the "
             "cut one left out", path)
    elif unwritten:
        warn("the TDMS file was not closed properly (its last segment's length was never "
             "written): read to the end of the file, its last values may be missing", path)
    return f


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole); a
    file cut short is read to its last whole segment, and says so."""
    nptdms = need("nptdms", EXTRA, path, ".tdms")
    f = _open(nptdms, path)
    out: dict[str, Series] = {}
    starts = [s for g in f.groups() for c in g.channels() if (s := _start(c)) is not None]
    ref = min(starts) if starts else 0.0
    for g in f.groups():
        tname, tcol = _group_time(g)
        for ch in g.channels():
            x = np.asarray(ch[:])
            if ch.name == tname or x.dtype.kind not in "biuf":
                continue
            t = _wave_time(ch)
            if t is not None and _start(ch) is not None:
                t = t + (_start(ch) - ref)
            elif t is None and tcol is not None and len(tcol) == len(x):
                t = tcol
            out[f"{g.name}/{ch.name}"] = Series(x.astype(float), t,
                                                ch.properties.get("unit_string"))
    return Signals(out)
