"""WPILib DataLog files (``.wpilog``) through robotpy-wpiutil's ``DataLogReader``; series.

Every numeric entry (``double``, ``float``, ``int64``, ``boolean``) is a series named by the
entry's name (``/drive/voltage``); the elements of a numeric array entry are ``name[k]``. Its
instants are the records' time stamps [s from the file's first record]. An entry's metadata,
when it is JSON with a ``unit`` (or ``units``) key, gives the unit.
"""

from __future__ import annotations

import json

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io.formats import Series, Signals, need

EXTENSIONS = (".wpilog",)
EXTRA = "wpilog"
#: entry type -> the record's getter
SCALARS = {"double": "getDouble", "float": "getFloat", "int64": "getInteger",
           "boolean": "getBoolean"}
ARRAYS = {"double[]": "getDoubleArray", "float[]": "getFloatArray",
          "int64[]": "getIntegerArray", "boolean[]": "getBooleanArray"}
MAX_ELEMENTS = 16


def _unit(metadata: str) -> str | None:
    try:
        obj = json.loads(metadata)
    except (ValueError, TypeError):
        return None
    if isinstance(obj, dict):
        u = obj.get("unit", obj.get("units"))
        return str(u) if u is not None else None
    return None


def _add(name, ts, value, times, values) -> None:
    times.setdefault(name, []).append(ts)
    values.setdefault(name, []).append(float(value))


def _record(rec, entry, times, values) -> None:
    name, typ = entry
    ts = rec.getTimestamp()
    if typ in SCALARS:
        _add(name, ts, getattr(rec, SCALARS[typ])(), times, values)
    elif typ in ARRAYS:
        arr = list(getattr(rec, ARRAYS[typ])())
        if 0 < len(arr) <= MAX_ELEMENTS:
            for k, v in enumerate(arr):
                _add(name if len(arr) == 1 else f"{name}[{k}]", ts, v, times, values)


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole)."""
    log = need("wpiutil.log", EXTRA, path, ".wpilog")
    reader = log.DataLogReader(path)
    if not reader.isValid():
        raise LogError("is not a WPILib DataLog (.wpilog) file: its header is not one", path)
    entries: dict[int, tuple[str, str]] = {}
    units: dict[str, str | None] = {}
    times: dict[str, list[int]] = {}
    values: dict[str, list[float]] = {}
    try:
        for rec in reader:
            if rec.isStart():
                d = rec.getStartData()
                entries[d.entry] = (d.name, d.type)
                units[d.name] = _unit(d.metadata)
            elif not rec.isControl() and rec.getEntry() in entries:
                _record(rec, entries[rec.getEntry()], times, values)
    except (ValueError, TypeError, RuntimeError) as exc:
        raise LogError(f"is not a readable .wpilog file ({str(exc)[:100]})", path) from None
    if not times:
        return Signals({})
    t0 = min(min(ts) for ts in times.values())
    out = {}
    for name, ts in times.items():
        base = name.split("[")[0]
        out[name] = Series(np.asarray(values[name], float),
                           (np.asarray(ts, dtype=np.int64) - t0).astype(float) * 1e-6,
                           units.get(base))
    return Signals(out)
