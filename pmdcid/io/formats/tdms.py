"""LabVIEW TDMS logs (``.tdms``) through nptdms: series named ``group/channel``.

A channel's instants come from its waveform properties (``wf_increment``, ``wf_start_offset``,
``wf_start_time``: channels started at different absolute times are aligned) or, without them,
from its group's time channel (one named ``t``, ``time``, ``Time``, ``timestamp`` or a
timestamp-typed channel: the group is then a table). The unit is the ``unit_string`` property.
"""

from __future__ import annotations

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io.formats import Series, Signals, need

EXTENSIONS = (".tdms",)
EXTRA = "tdms"
TIME_NAMES = ("t", "time", "Time", "timestamp", "Timestamp", "timestamps")


def _seconds(x: np.ndarray) -> np.ndarray:
    """Numbers as they are; datetimes as seconds [s] since 1970."""
    x = np.asarray(x)
    if x.dtype.kind == "M":
        return x.astype("datetime64[ns]").astype(np.int64).astype(float) * 1e-9
    return x.astype(float)


def _group_time(group) -> tuple[str | None, np.ndarray | None]:
    for ch in group.channels():
        if ch.name in TIME_NAMES or np.asarray(ch[:]).dtype.kind == "M":
            return ch.name, _seconds(ch[:])
    return None, None


def _wave_time(ch) -> np.ndarray | None:
    if "wf_increment" not in ch.properties:
        return None
    try:
        return np.asarray(ch.time_track(), dtype=float)
    except (KeyError, ValueError):
        return None


def _start(ch) -> float | None:
    st = ch.properties.get("wf_start_time")
    if st is None:
        return None
    return float(_seconds(np.asarray([st]))[0])


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole)."""
    nptdms = need("nptdms", EXTRA, path, ".tdms")
    try:
        f = nptdms.TdmsFile.read(path)
    except (ValueError, OSError, KeyError, EOFError) as exc:
        raise LogError(f"is not a readable TDMS file ({str(exc)[:100]})", path) from None
    out: dict[str, Series] = {}
    starts = [s for g in f.groups() for c in g.channels() if (s := _start(c)) is not None]
    ref = min(starts) if starts else 0.0
    for g in f.groups():
        tname, tcol = _group_time(g)
        for ch in g.channels():
            x = np.asarray(ch[:])
            if ch.name == tname or x.dtype.kind not in "biuf" or len(x) < 1:
                continue
            t = _wave_time(ch)
            if t is not None and _start(ch) is not None:
                t = t + (_start(ch) - ref)
            elif t is None and tcol is not None and len(tcol) == len(x):
                t = tcol
            out[f"{g.name}/{ch.name}"] = Series(x.astype(float), t,
                                                ch.properties.get("unit_string"))
    return Signals(out)
