"""Building a validated :class:`~pmdcid.io.logs.Log` from columns: the one set of checks.

Every way into a log goes through here: :func:`~pmdcid.io.logs.read_log` (CSV files, the CLI),
``Log.from_dataframe`` and ``Log.from_arrays`` (the library). :func:`frame_columns` applies a
column mapping (units, renames) to a table; :func:`validated_log` checks the time column (finite,
increasing; uniform, or loop-timed and resampled: :mod:`pmdcid.io.clock`), fills short NaN
gaps, runs the plausibility checks (:mod:`pmdcid.io.checks`) and derives speed from angle
or the reverse (:mod:`pmdcid.io.derive`).

The functions that make a log take its class (``log_type``: :class:`~pmdcid.io.logs.Log`) from
their caller, so that this module, and the format readers calling it, never import the module
whose ``Log.from_*`` constructors call them: imports flow one way, with no cycle.
"""

from __future__ import annotations

import numpy as np

from pmdcid.errors import LogError, short_list, warn
from pmdcid.io.checks import held_glitches
from pmdcid.io.clock import INPUTS
from pmdcid.io.csvsource import column_specs, is_datetime_column, numeric_column
from pmdcid.io.headers import unit_of
from pmdcid.io.mapping import CANONICAL, SETPOINTS, ColumnMap, ColumnSpec, parse_mapping


def as_mapping(columns=None, map_file=None, cutoff_hz: float | None = None) -> ColumnMap:
    """A :class:`ColumnMap` from the library's ways of giving one: a ``ColumnMap``, a dict
    ``{"omega": "speed*rpm"}``, a list of ``"omega=speed*rpm"`` items or one such string, plus
    an optional mapping file (its entries overridden by ``columns``) and a cut-off [Hz]."""
    if isinstance(columns, ColumnMap):
        base = parse_mapping((), map_file) if map_file is not None else ColumnMap()
        out = base.merged(columns)
    else:
        if isinstance(columns, dict):
            items = [f"{k}={v}" for k, v in columns.items()]
        elif isinstance(columns, str):
            items = [columns]
        else:
            items = list(columns or ())
        out = parse_mapping(items, map_file)
    if cutoff_hz is not None:
        out.cutoff_hz = float(cutoff_hz)
    return out


def frame_columns(df, mapping: ColumnMap, path: str, units: dict | None = None):
    """Canonical SI columns (name -> float array), the other numeric columns of ``df`` (at most
    :data:`MAX_EXTRA`), and the mapping-file lines skipped because their sources are absent.

    A canonical column comes from the column of that name or from ``mapping`` (renames, units,
    expressions: :mod:`pmdcid.io.csvsource`); raises :class:`LogError` naming the column for a
    missing source, a text cell, or no time column. ``units``: column -> the unit a file stores
    with it (Parquet), applied where the mapping reads a column as it stands
    (:mod:`pmdcid.io.formats.units`).
    """
    cols = [str(c) for c in df.columns]
    specs, skipped = column_specs(cols, mapping, CANONICAL, path)
    if "t" not in specs:
        specs["t"] = _time_spec(df, cols, specs, skipped, path, units)
    if units:
        from pmdcid.io.formats.units import apply_stored_units

        specs = apply_stored_units(specs, units, path)
    cache: dict[str, np.ndarray] = {}
    times = set(specs["t"].refs)

    def get(name: str) -> np.ndarray:
        if name not in cache:
            cache[name] = numeric_column(df, name, path, times=name in times)
        return cache[name]

    data: dict[str, np.ndarray] = {}
    for canon, spec in specs.items():
        with np.errstate(all="ignore"):
            data[canon] = np.broadcast_to(np.asarray(spec.evaluate(get), dtype=float),
                                          (len(df),)).copy()
    used = {r for spec in specs.values() for r in spec.refs}
    extra = {}
    for c in [c for c in cols if c not in used][:MAX_EXTRA]:
        x = numeric_column(df, c, path, strict=False)
        if np.isfinite(x).any():
            extra[c] = x
    return data, extra, skipped


def _stored_time(units: dict | None, name: str) -> bool:
    """True when the file stores column ``name`` with a unit of time (a Parquet timestamp)."""
    unit = (units or {}).get(name)
    hit = unit_of(unit) if unit else None
    return hit is not None and hit[1] == "time"


def _time_spec(df, cols: list[str], specs: dict, skipped: dict, path: str,
               units: dict | None = None) -> ColumnSpec:
    """The time column of a table without a ``t`` column or mapping: the one column that holds
    times as such (ISO 8601 date-times, pandas date-times or durations, a column the file
    stores in a unit of time), if there is one; else a :class:`LogError` saying why there is
    none."""
    used = {r for spec in specs.values() for r in spec.refs}
    dates = [c for c in cols if c not in used
             and (is_datetime_column(df, c) or _stored_time(units, c))]
    if len(dates) == 1:
        kind = getattr(getattr(df[dates[0]], "dtype", None), "kind", "")
        if _stored_time(units, dates[0]) or kind == "m":  # (date-time text says so itself)
            warn(f"column '{dates[0]}' is stored as times: read as t, in seconds", path)
        return ColumnSpec("t", dates[0], text=f"t={dates[0]}")
    if len(dates) > 1:
        raise LogError(f"has no time column 't' and several columns of times "
                       f"({short_list(dates)}): map one with -c t=SOURCE", path)
    seps = [(";", "semicolon"), ("\t", "tab"), ("|", "bar"), (" ", "space")]
    sep = next((w for c, w in seps if len(cols) == 1 and c in cols[0]), None)
    if sep:
        raise LogError(f"looks {sep}-separated (header {cols[0][:40]!r}) but its rows do not "
                       "have as many separators as the header: make every row alike, or "
                       "convert the file to comma-separated CSV", path)
    why = f"; {skipped['t']}" if "t" in skipped else ""
    raise LogError(f"has no time column 't' (columns are {short_list(cols)}{why}; map one "
                   "with -c t=SOURCE)", path)


#: at most this many unmapped numeric columns are kept in ``Log.extra`` (a transposed export
#: of 120 000 columns must not cost 120 000 conversions)
MAX_EXTRA = 64
#: NaN cells are interpolated (with a warning) up to this fraction of a column ...
NAN_MAX_FRACTION = 0.01
#: ... and this many consecutive samples
NAN_MAX_RUN = 10
#: |values| at or above this are instrument overload / not-a-number markers (SCPI's 9.9e37),
#: never a motor's voltage, current, speed or angle in SI units
OVERLOAD = 1e30


def fill_nans(name: str, x: np.ndarray, path: str) -> np.ndarray:
    """``x`` with short NaN gaps filled (a warning): an input (``v``, ``tau``: zero-order held,
    CONTRACT.md) holds the sample before the gap (a gap at the start takes the first sample
    after it), a measurement is interpolated linearly; too many, an inf or an overload marker
    (|x| >= :data:`OVERLOAD`): LogError."""
    big = np.abs(np.nan_to_num(x, nan=0.0, posinf=0.0, neginf=0.0)) >= OVERLOAD
    if big.any():
        row = int(np.flatnonzero(big)[0])
        raise LogError(f"column '{name}' holds {x[row]:.3g} (data row {row + 1}): an instrument "
                       "overload or not-a-number marker, not a measurement; fix or remove that "
                       "row", path)
    bad = ~np.isfinite(x)
    if not bad.any():
        return x
    if np.isinf(x).any():
        row = int(np.flatnonzero(np.isinf(x))[0])
        raise LogError(f"column '{name}' holds an infinite value (data row {row + 1}): "
                       "fix or remove that row", path)
    nbad = int(bad.sum())
    edges = np.diff(np.concatenate(([0], bad.view(np.int8), [0])))
    runs = np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)
    first = int(np.flatnonzero(bad)[0])
    if nbad / len(x) > NAN_MAX_FRACTION or runs.max() > NAN_MAX_RUN or bad.all():
        raise LogError(
            f"column '{name}' has {nbad} missing/NaN values (first at data row {first + 1}, "
            f"longest gap {int(runs.max())} samples): too many to fill; clean or cut the log",
            path)
    good = np.flatnonzero(~bad)
    x = x.copy()
    if name in INPUTS:
        x[bad] = x[held_index(bad, good)]
        how = "holding the sample before (the input is zero-order held)"
    else:
        x[bad] = np.interp(np.flatnonzero(bad), good, x[good])
        how = "linear interpolation"
    warn(f"column '{name}': filled {nbad} NaN value(s) by {how}", path)
    return x


def held_index(bad: np.ndarray, good: np.ndarray) -> np.ndarray:
    """For each sample flagged ``bad``, the index of the last good sample before it (the first
    good one when none is before); ``good``: the indices of the good samples, ascending."""
    k = np.searchsorted(good, np.flatnonzero(bad)) - 1
    return good[np.maximum(k, 0)]


def validated_log(log_type: type, path: str, data: dict[str, np.ndarray],
                  extra: dict | None = None, meta: dict | None = None,
                  cutoff_hz: float | None = None, *, skipped: dict | None = None,
                  defer: bool = False, resampled=None):
    """The checked ``log_type`` (:class:`~pmdcid.io.logs.Log`) of canonical SI columns ``data``
    (``t`` [s] among them).

    The time column is examined (:func:`pmdcid.io.clock.examine`): a uniform one is put on its
    grid from 0 (the original kept as ``t_file``); a loop-timed one is resampled onto a uniform
    grid (the input held, measurements interpolated; ``log.resampled`` keeps the file's
    instants, one line says so). ``resampled``: the :class:`~pmdcid.io.clock.Resampling` of
    columns already put on a uniform grid by a reader (signals on several clocks). A column with
    no number at all is dropped, as if absent (a warning; a command needing it says it lacks it,
    and why). NaN gaps are filled (:func:`fill_nans`); the plausibility checks run; speed is
    derived from the angle, or the angle from the speed, when one is missing.
    """
    from pmdcid.io.clock import examine, resample_columns

    data = {k: np.asarray(v, dtype=float) for k, v in data.items()}
    t = data.pop("t")
    clock = examine(t, path)
    skipped = dict(skipped or {})
    for canon in [c for c, x in data.items() if len(x) and np.isnan(x).all()]:
        del data[canon]  # a column with no number at all: as if absent
        skipped[canon] = f"column '{canon}' is empty"
        warn(f"column '{canon}' is empty (no number in any row): ignored", path)
    for canon in list(data):
        data[canon] = fill_nans(canon, data[canon], path)
    for canon in set(INPUTS) & set(data):
        data[canon] = held_glitches(canon, data[canon], path)
    extra = {c: x for c, x in (extra or {}).items() if np.isfinite(x).all()}
    extra.update({c: data.pop(c) for c in SETPOINTS if c in data})  # mapped set-points
    if not clock.uniform:
        data, extra, resampled = resample_columns(t, data, clock, extra)
    t_file = clock.grid if resampled is not None else t
    t = clock.grid - clock.grid[0]
    log = log_type(path=path, t=t, data=data, meta=dict(meta or {}), extra=extra,
              cutoff_hz=cutoff_hz, t_file=t_file, skipped=skipped,
              resampled=resampled)
    if resampled is not None:
        log.notes.append(resampled.note)
        warn(resampled.note, path)
    from pmdcid.io.checks import check_log

    log.issues = check_log(log)
    if not defer:  # a stage about to write a model refuses instead (identify/plausibility.py)
        for msg in log.issues:
            warn(msg, path)
    if ("omega" in data) != ("theta" in data):
        from pmdcid.io.derive import derive_missing

        derive_missing(log, cutoff_hz)
    return log


def log_from_frame(log_type: type, df, mapping: ColumnMap | None = None,
                   path: str = "<dataframe>", meta: dict | None = None):
    """A checked ``log_type`` from a pandas DataFrame (columns mapped as for a CSV file)."""
    mapping = mapping or ColumnMap()
    cols = [" ".join(str(c).splitlines()).strip() for c in df.columns]
    dups = sorted({c for c in cols if cols.count(c) > 1})
    if dups:
        raise LogError(f"names column(s) {', '.join(dups)} more than once: rename one", path)
    if len(df) == 0:
        raise LogError("has no data rows", path)
    df = _index_as_column(df.set_axis(cols, axis=1))
    data, extra, skipped = frame_columns(df, mapping, path)
    log = validated_log(log_type, path, data, extra, meta, mapping.cutoff_hz, skipped=skipped)
    log.sources = mapping.sources(data)
    return log


def _index_as_column(df):
    """``df`` with its index as a column where the index holds the time, as pandas keeps time
    series: date-times, durations, or numbers under a name (``t``, ``time [ms]``); the index
    is then read as any column (a date-time column is the time unless another is mapped).
    A mapping may name it (``columns={"t": "stamp"}`` for an index named ``stamp``). Unchanged
    when a column has the index's name, or the index is pandas' default row numbering."""
    import pandas as pd

    idx = df.index
    if isinstance(idx, pd.MultiIndex):
        return df
    timed = isinstance(idx, (pd.DatetimeIndex, pd.TimedeltaIndex))
    if not timed and (idx.name is None or idx.dtype.kind not in "iuf"):
        return df
    name = str(idx.name) if idx.name is not None else "time"
    if name in df.columns:
        return df
    return df.reset_index(names=name)


def log_from_arrays(log_type: type, t, name: str = "<arrays>", cutoff_hz: float | None = None,
                    meta: dict | None = None, **columns):
    """A checked ``log_type`` from 1-D arrays in SI units (``t`` [s], ``v`` [V], ...)."""
    data = {"t": np.asarray(t, dtype=float)}
    for k, v in columns.items():
        if v is not None:
            data[k] = np.asarray(v, dtype=float)
    for k, a in data.items():
        if a.ndim != 1 or len(a) != len(data["t"]):
            raise LogError(f"column '{k}' must be a 1-D array as long as t ({len(data['t'])} "
                           f"samples); it has shape {a.shape}", name)
    if len(data) == 1:
        raise LogError("needs an input ('v' [V] or 'tau' [N m]) and a measurement besides t",
                       name)
    return validated_log(log_type, name, data, None, meta, cutoff_hz)
