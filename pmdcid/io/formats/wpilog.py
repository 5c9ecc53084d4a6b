"""WPILib DataLog files (``.wpilog``) through robotpy-wpiutil's ``DataLogReader``; series.

Every numeric entry (``double``, ``float``, ``int64``, ``boolean``) is a series named by the
entry's name (``/drive/voltage``); the elements of a numeric array entry are ``name[k]``. Its
instants are the records' time stamps [s from the file's first record]. An entry's metadata
gives the unit when it is JSON with a ``unit`` (or ``units``) key, or when it is plain text, as
WPILib's own ``SysIdRoutineLog`` writes it: the unit's name (``Volt``, ``Rotation``, ``Rotation
per Second``: the entries ``voltage-shooter-Shooter``, ``velocity-shooter-Shooter`` SysId reads).
Ignoring those had a bare ``-c omega=velocity-shooter-Shooter`` read rotations per second as
rad/s, 2 pi too slow, with no word.

A DataLog has no footer: a robot that loses power leaves a file whose last record is cut short,
which the reader would pass over without a word. :func:`intact_end` walks the records' framing
(each record's header byte gives the lengths of its fields) to the end of the last whole
record; a file cut short is read up to there with one warning saying how much was kept.
"""

from __future__ import annotations

import json

import numpy as np

from pmdcid.errors import LogError, warn
from pmdcid.io.formats import Series, Signals, byte_count, need

EXTENSIONS = (".wpilog",)
EXTRA = "wpilog"
#: a time that looks like ms, us or ns (:func:`pmdcid.io.formats.own_time_fix`)
TIME_UNIT_FIX = "write each record's time stamp in microseconds, a DataLog's unit"
#: entry type -> the record's getter
SCALARS = {"double": "getDouble", "float": "getFloat", "int64": "getInteger",
           "boolean": "getBoolean"}
ARRAYS = {"double[]": "getDoubleArray", "float[]": "getFloatArray",
          "int64[]": "getIntegerArray", "boolean[]": "getBooleanArray"}
MAX_ELEMENTS = 16


#: longest plain-text metadata read as a unit's name (longer text is a note, not a unit)
PLAIN_UNIT = 40


def _unit(metadata: str) -> str | None:
    try:
        obj = json.loads(metadata)
    except (ValueError, TypeError):
        text = metadata.strip() if isinstance(metadata, str) else ""
        # plain text, as SysIdRoutineLog writes Volts.name(): a unit's name, not a sentence
        return text if 0 < len(text) <= PLAIN_UNIT and "\n" not in text else None
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


HEADER = 12  # "WPILOG", version (2 bytes), length of the extra header (4 bytes)


def intact_end(data) -> tuple[int, int, int]:
    """(end of the last whole record [byte], records before it, bytes the cut record lacks:
    0 for a file that ends on a record's end) of a DataLog's bytes ``data`` (header checked)."""
    size = len(data)
    pos = HEADER + int.from_bytes(data[8:12], "little")
    if pos > size:
        return HEADER, 0, pos - size
    count = 0
    while pos < size:
        head = data[pos]
        n_entry, n_size, n_time = (head & 3) + 1, ((head >> 2) & 3) + 1, ((head >> 4) & 7) + 1
        start = pos + 1 + n_entry
        if start + n_size > size:
            return pos, count, start + n_size + n_time - size
        end = start + n_size + n_time + int.from_bytes(data[start:start + n_size], "little")
        if end > size:
            return pos, count, end - size
        pos, count = end, count + 1
    return pos, count, 0


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole); a file
    cut short within its last record is read to the end of its last whole record, and says so."""
    log = need("wpiutil.log", EXTRA, path, ".wpilog")
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except OSError as exc:
        raise LogError(f"cannot be read ({exc.strerror or exc})", path) from None
    if not log.DataLogReader(data[:HEADER], path).isValid():
        raise LogError("is not a WPILib DataLog (.wpilog) file: its header is not one", path)
    end, count, missing = intact_end(data)
    if missing and count == 0:
        raise LogError(f"the .wpilog file is cut short ({byte_count(missing)} of its first record "
                       "missing): it was not closed properly and holds no whole record", path)
    reader = log.DataLogReader(memoryview(data)[:end], path)
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
    stamps = list(times.values())
    if missing:
        last = (max(max(ts) for ts in stamps) - min(min(ts) for ts in stamps)) * 1e-6 \
            if stamps else 0.0
        warn(f"the .wpilog file is cut short ({byte_count(missing)} of its last record missing: it "
             f"was not closed properly); read the {count} whole records before the cut "
             f"({end} of {len(data)} bytes, {last:.6g} s of data)", path)
    if not times:
        return Signals({})
    t0 = min(min(ts) for ts in stamps)
    out = {}
    for name, ts in times.items():
        base = name.split("[")[0]
        out[name] = Series(np.asarray(values[name], float),
                           (np.asarray(ts, dtype=np.int64) - t0).astype(float) * 1e-6,
                           units.get(base))
    return Signals(out)
