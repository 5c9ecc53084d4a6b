"""From a file's signals to a checked :class:`~pmdcid.io.logs.Log`: tables and series.

- A **table** (Parquet, ``.mat``): columns sharing one time column, mapped exactly as a CSV
  file's (:func:`pmdcid.io.build.frame_columns`), then checked (uniform or loop-timed).
- **Series** (MCAP, wpilog, TDMS, MDF): each signal on its own clock. The mapped signals are put
  on the **input's clock** (the instants of the signal the ``v`` or ``tau`` mapping reads):
  the input held (zero-order hold), every measurement interpolated linearly at those instants,
  over the span where every mapped signal has samples. When the input's own instants are not
  uniform (or a measurement comes at least twice as fast: :data:`REFINE`), they become a uniform
  grid (:mod:`pmdcid.io.clock`) at the finer of the input's and the fastest measurement's median
  intervals: the input's mean over each step (held across gaps: a command logged when it
  changes), measurements interpolated, in one step. A **current** on a uniform clock of its
  own (the speed, for a torque input), the fastest measurement, is compared where it was taken
  instead: its instants are the grid and the input is averaged over each step
  (:meth:`_OnClock._lead`; its slope jumps at an input edge, which interpolation would bend
  at first order). One line says so.
"""

from __future__ import annotations

import numpy as np

from pmdcid.errors import LogError, short_list, warn
from pmdcid.io.clock import (
    GAP_MAX,
    INPUTS,
    JITTER_TOL,
    Clock,
    Resampling,
    examine,
    held_mean,
    interpolated,
    loop_note,
    zoh,
)
from pmdcid.io.formats import Signals, extension
from pmdcid.io.formats.units import apply_stored_units
from pmdcid.io.mapping import CANONICAL, ColumnMap

#: a measurement sampled this many times faster than a uniform input (or more) sets the grid:
#: the input is held on the measurement's rate instead of decimating the measurement
REFINE = 0.5
#: names a table's time column goes by when no ``-c t=...`` names it
TIME_NAMES = ("t", "time", "Time", "timestamp", "timestamps")


def table_time(sig: Signals, column: str) -> np.ndarray | None:
    """The time column a table's ``column`` goes with, for ``pmdcid channels``: a column of
    :data:`TIME_NAMES` as long as it, in its own struct first (``log.t`` for ``log.v``), else at
    the top; None when there is none."""
    prefix = column.rsplit(".", 1)[0] + "." if "." in column else ""
    for name in [prefix + n for n in TIME_NAMES] + list(TIME_NAMES):
        s = sig.series.get(name)
        if s is not None and len(s.x) == len(sig.series[column].x):
            return s.x
    return None


def _time_source(sig: Signals, mapping: ColumnMap) -> str | None:
    spec = mapping.specs.get("t")
    if spec is not None:
        return spec.refs[0] if spec.refs[0] in sig.series else None
    return "t" if "t" in sig.series else None


def table_log(log_type: type, p: str, sig: Signals, mapping: ColumnMap, defer: bool = False):
    """A table's columns as a CSV file's: the time column ``t`` (or ``-c t=SOURCE``) and the
    columns as long as it; a mapped column of another length is one clear line."""
    from pmdcid.io.build import frame_columns, validated_log
    from pmdcid.io.plain import PlainFrame

    tname = _time_source(sig, mapping)
    n = len(sig.series[tname].x) if tname is not None else \
        max((len(s.x) for s in sig.series.values()), default=0)
    _check_lengths(sig, mapping, tname, n, p)
    names = [k for k, s in sig.series.items() if len(s.x) == n]
    if n == 0:
        raise LogError("has no data rows", p)
    frame = PlainFrame(names, [np.asarray(sig.series[k].x, dtype=float) for k in names])
    data, extra, skipped = frame_columns(frame, mapping, p,
                                         units={k: sig.series[k].unit for k in names})
    log = validated_log(log_type, p, data, extra, sig.meta, mapping.cutoff_hz, skipped=skipped,
                        defer=defer)
    log.sources = mapping.sources(data)
    return log


def _check_lengths(sig: Signals, mapping: ColumnMap, tname: str | None, n: int, p: str) -> None:
    """Refuse a column the log would use, mapped or by its canonical name (``omega`` with no
    ``-c omega=...``), whose length is not the time column's ``n``: left out, the command would
    say it lacks that column, as if the file held none."""
    used = {r for spec in mapping.specs.values() for r in spec.refs}
    used |= {c for c in CANONICAL if c not in mapping.specs}
    for r in sorted(used):
        s = sig.series.get(r)
        if s is not None and len(s.x) != n:
            raise LogError(f"'{r}' has {len(s.x)} samples where the time column "
                           f"'{tname or 't'}' has {n}: the columns of a {extension(p)} log share "
                           f"its time column, so it cannot be used as it is (save '{r}' at the "
                           "time column's instants)", p)


def _sorted(sig: Signals, name: str, p: str):
    """Signal ``name``'s instants and values in time order (stable)."""
    s = sig.series[name]
    if len(s.x) == 0:
        raise LogError(f"signal '{name}' is in the file but has 0 samples (nothing was recorded "
                       "in it): map a signal that has samples, or record it again", p)
    if s.t is None:  # a TDMS channel without waveform timing or a time channel of its length
        raise LogError(f"signal '{name}' has no time stamps of its own in the file (a TDMS "
                       "channel needs the waveform properties wf_increment and wf_start_offset, "
                       "or a time channel as long as it in its group): export the channels "
                       "with their timing", p)
    t, x = np.asarray(s.t, float), np.asarray(s.x, float)
    if len(t) < 2:
        raise LogError(f"signal '{name}' has {len(t)} sample(s): too few to use", p)
    if (np.diff(t) < 0).any():
        k = np.argsort(t, kind="stable")
        t, x = t[k], x[k]
    return t, x


def _check_gaps(name: str, t: np.ndarray, lo: float, hi: float, p: str) -> None:
    """A measurement whose samples stop for more than :data:`GAP_MAX` of its median interval
    inside the span used: refused (interpolating across it would invent the signal)."""
    inside = t[(t >= lo) & (t <= hi)]
    if len(inside) < 2:
        raise LogError(f"signal '{name}' has fewer than 2 samples where the input has samples "
                       f"(t={lo:g} to {hi:g} s): the signals do not overlap in time", p)
    dtv = np.diff(inside)
    med = float(np.median(dtv[dtv > 0])) if (dtv > 0).any() else 0.0
    if med > 0 and dtv.max() > GAP_MAX * med:
        k = int(np.argmax(dtv))
        raise LogError(f"signal '{name}' has a gap of {dtv[k]:.3g} s after t={inside[k]:g} s "
                       f"(its samples are {med:.3g} s apart): cut the log there", p)


def _specs(p: str, sig: Signals, mapping: ColumnMap):
    from pmdcid.io.csvsource import column_specs

    names = list(sig.series)
    specs, skipped = column_specs(names, mapping, CANONICAL, p)
    if "t" in specs and "t" in mapping.specs:
        raise LogError(f"-c t=...: the signals of a {extension(p)} file carry their own time "
                       "stamps; map the signals only", p)
    specs.pop("t", None)
    specs = apply_stored_units(specs, {k: s.unit for k, s in sig.series.items()}, p)
    if not specs:
        raise LogError(f"no signal is mapped to a canonical column: name them with e.g. "
                       f"-c v=SOURCE -c omega=SOURCE (signals: {short_list(names)}; "
                       "`pmdcid channels FILE` lists them)", p)
    return specs, skipped


def _finest(series: dict, names) -> float | None:
    """The shortest median interval [s] among the series ``names`` (None: none)."""
    meds = []
    for n in names:
        d = np.diff(series[n][0])
        d = d[d > 0]
        if len(d):
            meds.append(float(np.median(d)))
    return min(meds) if meds else None


def _sparse(instants: np.ndarray, fine: float, hi: float) -> bool:
    """An input whose own instants cannot be the grid: under 3 in the span, at least twice as
    far apart as the fastest measurement's (:data:`REFINE`), with a gap of :data:`GAP_MAX`
    intervals (a command logged when it changes), or ending well before the measurements."""
    if len(instants) < 3:
        return True
    d = np.diff(instants)
    med = float(np.median(d[d > 0])) if (d > 0).any() else 0.0
    return (med * REFINE > fine or float(d.max()) > GAP_MAX * med
            or hi - instants[-1] > GAP_MAX * med)


class _OnClock:
    """The mapped signals at the input's instants (uniform clock) or on a uniform grid."""

    def __init__(self, p: str, sig: Signals, specs: dict):
        self.p, self.sig, self.specs = p, sig, specs
        self.input = next((c for c in INPUTS if c in specs), None)
        first = specs[self.input] if self.input else next(iter(specs.values()))
        self.clock_name = first.refs[0]
        used = sorted({r for spec in specs.values() for r in spec.refs})
        self.series = {r: _sorted(sig, r, p) for r in used}
        self.lo = max(t[0] for t, _ in self.series.values())
        held = {r for c in INPUTS if c in specs for r in specs[c].refs}
        # an input holds its last value: only the measurements end the span
        self.hi = min([t[-1] for r, (t, _) in self.series.items() if r not in held]
                      or [t[-1] for t, _ in self.series.values()])
        t_in = self.series[self.clock_name][0]
        self.instants = t_in[(t_in >= self.lo) & (t_in <= self.hi)]
        measured = {r for c, spec in specs.items() if c not in INPUTS for r in spec.refs}
        fine = _finest(self.series, measured)
        self.refined = bool(self.input and fine and _sparse(self.instants, fine, self.hi))
        if self.refined:  # a slow or sparse command, a fast encoder: the measurement's rate
            m = int(np.floor((self.hi - self.lo) / fine * (1 + 1e-12))) + 1
            d = np.diff(self.instants)
            per = float(np.median(d)) if len(d) else self.hi - self.lo  # the input's interval
            self.clock = Clock(False, fine, self.lo + fine * np.arange(m), spread=(per, per))
        else:
            try:  # a grid no coarser than the fastest measurement's median interval
                self.clock = examine(self.instants, p, period=fine, held_gaps=True)
            except LogError as exc:
                msg = str(exc).removeprefix(f"{p}: ")
                raise LogError(f"signal '{self.clock_name}' (the input's clock): {msg}",
                               p) from None
        self.at = self.instants if self.clock.uniform else self.clock.grid
        #: the grid is the input's own instants (the input exact, as logged)
        self.on_input = self.clock.uniform
        #: the measurement whose own instants are the grid instead (None: none is)
        self.lead = self._lead(specs)
        if self.lead is not None:
            t_lead = self.series[self.lead][0]
            t_lead = t_lead[(t_lead >= self.lo) & (t_lead <= self.hi)]
            self.clock = Clock(True, float(np.median(np.diff(t_lead))), t_lead)
            self.at, self.on_input = t_lead, False
        for canon, spec in specs.items():
            if canon not in INPUTS:
                for r in spec.refs:
                    _check_gaps(r, self.series[r][0], self.lo, self.hi, p)

    def _lead(self, specs: dict) -> str | None:
        """The measured signal whose own instants become the grid: the one whose slope jumps at
        an edge of the input (the current under a voltage step, the speed under a torque step),
        which linear interpolation across the edge would bend by a first-order error (docs/io.md,
        'Clocks'), when it is the fastest measurement, its instants in the span are uniform and
        are not the input's. None: the grid stays as before (the input's clock, or a uniform
        grid for a loop-timed or sparse input); a smoother signal (the speed or angle under a
        voltage) is interpolated at second order, with the input exact."""
        kinked = {"v": "i", "tau": "omega"}.get(self.input)
        if kinked not in specs:
            return None
        name = specs[kinked].refs[0]
        t = self.series[name][0]
        t = t[(t >= self.lo) & (t <= self.hi)]
        if len(t) < 3 or np.array_equal(t, self.instants):
            return None
        try:
            clock = examine(t, self.p)
        except LogError:
            return None
        if not clock.uniform:
            return None
        best = (name, clock.period)
        fine = _finest(self.series, {s.refs[0] for c, s in specs.items() if c not in INPUTS})
        if best[1] > fine * (1 + JITTER_TOL):
            return None  # a faster measurement is loop-timed: the grid as before
        # a measurement as fast on the input's own clock: that clock stays the grid
        for canon, spec in specs.items():
            t = self.series[spec.refs[0]][0]
            t = t[(t >= self.lo) & (t <= self.hi)]
            if canon not in INPUTS and np.array_equal(t, self.instants) and len(t) > 2 \
                    and float(np.median(np.diff(t))) <= best[1] * (1 + JITTER_TOL):
                return None
        return best[0]

    def _held_union(self, spec):
        """The input expression on the union of its signals' instants (each held), from the
        last instant at or before the span's start (the value held into it)."""
        refs = spec.refs
        union = np.unique(np.concatenate([self.series[r][0] for r in refs]))
        first = max(int(np.searchsorted(union, self.lo, side="right")) - 1, 0)
        keep = (union >= self.lo) & (union <= self.hi)
        if self.lead is not None:
            keep[first] = True
        union = union[keep]
        with np.errstate(all="ignore"):
            u = spec.evaluate(lambda n: zoh(*self.series[n], union))
        return union, np.broadcast_to(np.asarray(u, float), union.shape).copy()

    def column(self, canon: str) -> np.ndarray:
        spec = self.specs[canon]
        if canon in INPUTS:
            tu, u = self._held_union(spec)
            return zoh(tu, u, self.at) if self.on_input else held_mean(tu, u, self.at)
        with np.errstate(all="ignore"):
            y = spec.evaluate(lambda n: interpolated(*self.series[n], self.at))
        return np.broadcast_to(np.asarray(y, float), self.at.shape).copy()

    def same_clock(self) -> bool:
        """Every mapped signal has exactly the input's instants (nothing interpolated)."""
        ref = self.series[self.clock_name][0]
        return all(len(t) == len(ref) and np.array_equal(t, ref)
                   for t, _ in self.series.values())

    def input_period(self) -> float:
        """The input's median interval [s] in the span (the span's length if it has one)."""
        d = np.diff(self.instants)
        return float(np.median(d)) if len(d) else self.hi - self.lo

    def note(self, measured: list[str]) -> str:
        hz = 1.0 / self.clock.period
        what = ", ".join(measured) if measured else "nothing"
        span = f"t={self.lo:.6g} to {self.hi:.6g} s where every signal has samples"
        if self.lead is not None:
            others = [m for m in measured if self.specs[m].refs[0] != self.lead]
            rest = f", {', '.join(others)} interpolated linearly" if others else ""
            return (f"signals on different clocks put on the clock of '{self.lead}' ({hz:.4g} "
                    f"Hz, {span}), compared where it was taken: the input '{self.clock_name}' "
                    f"({1.0 / self.input_period():.4g} Hz) held and averaged over each step"
                    f"{rest} (docs/io.md, 'Clocks')")
        if self.refined:
            return (f"signals on different clocks put on a uniform {hz:.4g} Hz grid, the fastest "
                    f"measurement's ({span}): the input '{self.clock_name}' "
                    f"({1.0 / self.clock.spread[0]:.4g} Hz) held on it, {what} interpolated "
                    "linearly")
        return (f"signals on different clocks put on the input's clock ('{self.clock_name}', "
                f"{hz:.4g} Hz, {span}): the input held, {what} interpolated linearly")


def series_log(log_type: type, p: str, sig: Signals, mapping: ColumnMap, defer: bool = False):
    """Series on their own clocks -> a checked :class:`~pmdcid.io.logs.Log` (module doc)."""
    from pmdcid.io.build import validated_log

    specs, skipped = _specs(p, sig, mapping)
    on = _OnClock(p, sig, specs)
    data = {"t": np.asarray(on.at, float)}
    for canon in specs:
        data[canon] = on.column(canon)
    measured = [c for c in specs if c not in INPUTS]
    notes = [] if on.same_clock() else [on.note(measured)]
    resampled = None
    if not on.on_input:
        loop = [] if on.refined or on.lead else [loop_note(on.clock, len(on.instants), measured)]
        # simulate writes at the input's instants, or on the grid for a slow or sparse input
        t_out = on.clock.grid if on.refined else on.instants
        inputs = {c: zoh(*on._held_union(specs[c]), t_out) for c in specs if c in INPUTS}
        resampled = Resampling(t_out, inputs, on.clock.grid, "; ".join([*notes, *loop]),
                               measured)
    log = validated_log(log_type, p, data, {}, sig.meta, mapping.cutoff_hz, skipped=skipped,
                        defer=defer, resampled=resampled)
    log.sources = mapping.sources(data)
    if resampled is None:
        for note in notes:
            log.notes.append(note)
            warn(note, p)
    return log
