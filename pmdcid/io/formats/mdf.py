"""ASAM MDF logs (``.mf4``, ``.mdf``: MDF 3 and 4) through asammdf: series.

Each channel group has its own master (time) channel: its channels are series on that clock,
in physical values (the file's conversions applied), with the unit the file stores. A channel
is named by its own name where that is unique in the file, else ``group/channel`` with the
group's acquisition name (or its index when it has none or shares it). A channel named by its
own name may be named ``group/channel`` too (:attr:`Signals.aliases`).
"""

from __future__ import annotations

import gc
import sys
from collections import Counter

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io.formats import Series, Signals, need

EXTENSIONS = (".mf4", ".mdf")
EXTRA = "mdf"
#: a time that looks like ms, us or ns (:func:`pmdcid.io.formats.own_time_fix`)
TIME_UNIT_FIX = "write its master (time) channels in seconds, MDF's unit"


def _group_names(mdf) -> list[str]:
    acq = [(g.channel_group.acq_name or "").strip() for g in mdf.groups]
    count = Counter(acq)
    return [a if a and count[a] == 1 and "/" not in a else str(k) for k, a in enumerate(acq)]


def _channels(mdf) -> list[tuple[int, int, str]]:
    """(group, index, name) of every channel that is not its group's master channel."""
    out = []
    for gi, g in enumerate(mdf.groups):
        master = mdf.masters_db.get(gi)
        out += [(gi, ci, ch.name) for ci, ch in enumerate(g.channels) if ci != master]
    return out


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole)."""
    asammdf = need("asammdf", EXTRA, path, "MDF (.mf4/.mdf)")
    try:
        mdf = asammdf.MDF(path)
    except Exception as exc:  # asammdf raises many types on a foreign file  # noqa: BLE001
        why = f"{type(exc).__name__}: {str(exc)[:80]}"
    else:
        return _read(mdf)
    _collect_quietly()  # the exception, gone, held asammdf's half-built object
    raise LogError(f"is not a readable MDF file ({why})", path)


def _collect_quietly() -> None:
    """Collect what a failed ``asammdf.MDF(path)`` left: its half-built object's ``__del__``
    fails ('no attribute _file'), which Python would print on stderr after the one-line error."""
    hook = sys.unraisablehook
    sys.unraisablehook = lambda _unraisable: None
    try:
        gc.collect()
    finally:
        sys.unraisablehook = hook


def _read(mdf) -> Signals:
    """The signals of an open MDF file, which it closes."""
    try:
        chans = _channels(mdf)
        groups = _group_names(mdf)
        count = Counter(name for _, _, name in chans)
        out: dict[str, Series] = {}
        aliases: dict[str, str] = {}
        for gi, ci, name in chans:
            sig = mdf.get(name, group=gi, index=ci)
            x = np.asarray(sig.samples)
            if x.dtype.kind not in "biuf" or x.ndim != 1:
                continue
            key = name if count[name] == 1 else f"{groups[gi]}/{name}"
            if key == name:  # docs/io.md: '-c omega=motor/n_mot' names it by its group too
                aliases[f"{groups[gi]}/{name}"] = name
            out[key] = Series(x.astype(float), np.asarray(sig.timestamps, dtype=float),
                              sig.unit or None)
    finally:
        mdf.close()
    return Signals(out, aliases={a: n for a, n in aliases.items() if a not in out})
