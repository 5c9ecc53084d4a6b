"""Time bases: uniform logs, loop-timed logs, and signals on different clocks.

The kernel steps a uniform grid with the input held over each step. A log whose instants are
not uniform (a control loop that logs when it runs: 4-18 ms apart) or whose signals come on
clocks of their own (MCAP topics, wpilog entries, MDF channel groups) is put on one uniform
grid here, the one way for every format (docs/io.md, "Clocks"):

- the **input** (``v`` or ``tau``) is held from each of its logged instants (zero-order hold,
  as the drive applied it) and each grid step takes the **mean** of that held input over the
  step, so the input's integral over every step is exact. An input edge inside a step moves the
  state at the step's end by at most ``dt^2/(8 tau^2)`` of the edge's response (``tau`` the
  fastest time constant), and the error decays afterwards;
- each **measurement** is interpolated linearly at the grid instants from its own instants;
  between instants ``h`` apart the error is at most ``h^2/8 * max|y''|``, i.e.
  ``(h/tau)^2/8`` of a first-order response's change.

:func:`examine` decides what a time column is (uniform, loop-timed, or broken: time going back,
stamps that stand still beyond :data:`DUP_MAX_FRACTION`, gaps beyond :data:`GAP_MAX`);
:func:`held_mean` and :func:`interpolated` do the resampling; :class:`Resampling` remembers the
file's own instants so that ``simulate`` writes its output at them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import LogError

#: largest relative deviation of one sample period from the median still taken as uniform
JITTER_TOL = 0.02
#: a clock whose intervals deviate from the median in at most this fraction of rows is a
#: uniform logger with a few bad rows: a stamp that stands still or samples missing are refused
ANOMALY_FRACTION = 0.01
#: a loop-timed log's longest interval accepted [median intervals]; longer: refused
GAP_MAX = 10.0
#: a loop-timed log may repeat a time stamp (a loop faster than its clock's resolution) in at
#: most this fraction of its rows; repeated rows are merged (input: the last row, measured: mean)
DUP_MAX_FRACTION = 0.05
#: the canonical input columns: held, not interpolated
INPUTS = ("v", "tau")


@dataclass
class Clock:
    """What a time column is: ``uniform`` (within :data:`JITTER_TOL`) or loop-timed.

    ``period`` [s]: the grid's sample period (the median interval); ``grid`` [s, file time]:
    the uniform instants the kernel steps; ``groups``: for each distinct instant, the index of
    its first row (rows with a repeated stamp are merged), None when no stamp repeats."""

    uniform: bool
    period: float
    grid: np.ndarray
    groups: np.ndarray | None = None
    spread: tuple[float, float] = (0.0, 0.0)


@dataclass
class Resampling:
    """A log put on a uniform grid from other instants: ``t_file`` [s] the input's own instants
    (file time, every row), ``inputs`` the input column(s) there (SI), ``grid`` [s, file time],
    ``note`` the one line that says what was done."""

    t_file: np.ndarray
    inputs: dict[str, np.ndarray]
    grid: np.ndarray
    note: str
    measured: list[str] = field(default_factory=list)

    def at_file_instants(self, columns: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        """Columns on the grid -> at :attr:`t_file`: the input as logged, the others
        interpolated linearly (error: see the module doc); the instants after the grid's last
        (less than one period) extrapolated from its last step."""
        out = {}
        g = self.grid
        after = np.maximum(self.t_file - g[-1], 0.0)
        for name, col in columns.items():
            if name in self.inputs:
                out[name] = self.inputs[name]
                continue
            col = np.asarray(col, float)
            slope = (col[-1] - col[-2]) / (g[-1] - g[-2]) if len(g) > 1 else 0.0
            out[name] = np.interp(self.t_file, g, col) + slope * after
        return out


def _dt_text(x: float) -> str:
    return f"{x * 1e3:.3g} ms" if x < 1.0 else f"{x:.3g} s"


#: counters whose wrap a time column may show: bits, and the units a count may stand for [s]
COUNTER_BITS = (8, 16, 24, 32)
COUNTER_UNITS = ((1e-6, "microsecond"), (1e-3, "millisecond"), (1.0, "second"))
#: a step back of the time by at most this many sample periods is rows out of order (two rows
#: swapped, a row written late), not a counter's wrap: a wrap drops by the counter's whole range
OUT_OF_ORDER_PERIODS = 3.0


def _why_back(t: np.ndarray, row: int) -> str:
    """What a step back of the time after data row ``row + 1`` most likely is, and what to do:
    a logger that stopped (every later stamp 0), rows in reverse order, rows out of order (a
    step back of a few sample periods at most), a counter that wraps (the step back is a
    power-of-two count of a time unit), or just a time that must increase."""
    after = t[row + 1:]
    if len(after) > 1 and not after.any():
        return (f": every stamp from there to the end ({len(after)} rows) is 0, a logger that "
                f"stopped and padded its buffer; cut the log after data row {row + 1}")
    dtv = np.diff(t)
    if (dtv < 0).all():
        return (": every row is earlier than the one before, the rows are in reverse order: "
                "sort the log by time")
    period = float(np.median(dtv[dtv > 0])) if (dtv > 0).any() else 0.0
    drop = float(t[row] - t[row + 1])
    if period > 0 and drop <= OUT_OF_ORDER_PERIODS * period:
        return (f": rows out of order at t = {t[row]:g} s (the next row is {drop / period:.2g} "
                "sample period(s) earlier): sort the log by time")
    span = drop + period  # the counter's range, one period added back
    for bits in COUNTER_BITS:
        for unit, name in COUNTER_UNITS:
            if period > 0 and abs(span - 2.0**bits * unit) <= 2 * period:
                return (f": the time wraps from {t[row]:g} s to {t[row + 1]:g} s, a {bits}-bit "
                        f"{name} counter that overflows; unwrap it (add {2**bits} counts after "
                        "each wrap) or cut the log at the wrap")
    return ": time must increase"


def _finite_increasing(t: np.ndarray, path: str) -> np.ndarray:
    if not np.isfinite(t).all():
        row = int(np.flatnonzero(~np.isfinite(t))[0])
        raise LogError(f"time column has a missing or non-finite value (data row {row + 1}): "
                       "fix or remove that row", path)
    if len(t) < 3:
        raise LogError(f"has only {len(t)} data row(s): too short to use (at least 3)", path)
    dtv = np.diff(t)
    if (dtv < 0).any():
        row = int(np.flatnonzero(dtv < 0)[0])
        raise LogError(f"time goes back at data row {row + 2} (t={t[row + 1]:g} s)"
                       f"{_why_back(t, row)}", path)
    if not (dtv > 0).any():
        raise LogError("time stands still: every row has the same time stamp", path)
    return dtv


def _refuse_anomalies(t: np.ndarray, dtv: np.ndarray, med: float, path: str) -> None:
    """A uniform logger with a few bad rows: a repeated stamp or samples missing, refused as
    before loop-timed logs were read (the rows around them are suspect)."""
    if (dtv == 0).any():
        row = int(np.flatnonzero(dtv == 0)[0])
        raise LogError(f"time stands still at data row {row + 2} (t={t[row + 1]:g} s): time must "
                       "increase", path)
    gaps = np.flatnonzero(dtv > 1.5 * med)
    if len(gaps):
        k = int(gaps[0])
        raise LogError(
            f"samples missing: {len(gaps)} gap(s), the first of {dtv[k]:.3g} s after data "
            f"row {k + 1} (t={t[k]:g} s) where the period is {med:.3g} s; cut the log there "
            "or resample it to a uniform grid", path)


def _refuse_loop_faults(t: np.ndarray, dtv: np.ndarray, med: float, path: str,
                        gaps: bool = True) -> None:
    """A loop-timed log: too many repeated stamps, or (``gaps``) a gap beyond :data:`GAP_MAX`."""
    dups = int((dtv == 0).sum())
    if dups > DUP_MAX_FRACTION * len(t):
        row = int(np.flatnonzero(dtv == 0)[0])
        raise LogError(
            f"time stands still in {dups} rows ({100 * dups / len(t):.0f} %, the first at data "
            f"row {row + 2}): more than {100 * DUP_MAX_FRACTION:.0f} % of rows repeat a time "
            "stamp, the clock is too coarse for the loop; log a finer time", path)
    big = np.flatnonzero(dtv > GAP_MAX * med) if gaps else []
    if len(big):
        k = int(big[0])
        raise LogError(
            f"a gap of {dtv[k]:.3g} s after data row {k + 1} (t={t[k]:g} s), more than "
            f"{GAP_MAX:g} x the median interval {_dt_text(med)}: the input there is unknown; "
            "cut the log there", path)


def examine(t: np.ndarray, path: str, *, held_gaps: bool = False,
            period: float | None = None) -> Clock:
    """The :class:`Clock` of a time column [s]; a broken one raises :class:`LogError`.

    Uniform within :data:`JITTER_TOL`: the grid is ``t[0] + median * k`` (one instant per row).
    A uniform logger with a few bad rows (:data:`ANOMALY_FRACTION`): a stamp that stands still
    or samples missing are refused. Otherwise the log is loop-timed: repeated stamps are merged
    (:data:`DUP_MAX_FRACTION`), a gap beyond :data:`GAP_MAX` median intervals is refused, and
    the grid is ``t[0] + median * k`` up to the last instant.

    ``held_gaps``: the instants are an input series' own (a command topic, a wpilog entry logged
    when it changes): the input is held across any gap, so gaps and a few missing samples are
    not refused. ``period`` [s]: the grid's period when the instants are not uniform (default
    their median interval).
    """
    t = np.asarray(t, dtype=float)
    dtv = _finite_increasing(t, path)
    med = float(np.median(dtv))
    if med == 0.0:
        med = float(np.median(dtv[dtv > 0]))
    off = np.abs(dtv - med) > JITTER_TOL * med
    if not off.any():
        return Clock(True, med, t[0] + med * np.arange(len(t)))
    if off.mean() <= ANOMALY_FRACTION and not held_gaps and (
            (dtv == 0).any() or (dtv > 1.5 * med).any()):
        _refuse_anomalies(t, dtv, med, path)
    _refuse_loop_faults(t, dtv, med, path, gaps=not held_gaps)
    med = min(med, period) if period else med
    pos = dtv[dtv > 0]
    groups = None
    if (dtv == 0).any():
        groups = np.flatnonzero(np.concatenate(([True], dtv > 0)))
    m = int(np.floor((t[-1] - t[0]) / med * (1 + 1e-12))) + 1
    return Clock(False, med, t[0] + med * np.arange(m), groups,
                 (float(pos.min()), float(pos.max())))


def merged(x: np.ndarray, groups: np.ndarray, held: bool) -> np.ndarray:
    """Rows sharing a time stamp as one: the last row's value (``held``: an input, the loop's
    last command) or their mean (a measurement)."""
    if held:
        last = np.concatenate((groups[1:] - 1, [len(x) - 1]))
        return x[last]
    sums = np.add.reduceat(x, groups)
    counts = np.diff(np.concatenate((groups, [len(x)])))
    return sums / counts


def held_mean(t_src: np.ndarray, u: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The input ``u`` held from each instant of ``t_src`` (zero-order hold), averaged over each
    step ``[grid[k], grid[k+1])``; the last grid instant takes the value held there. Exact for a
    piecewise-constant input: its integral is piecewise linear between the instants."""
    t_src = np.asarray(t_src, float)
    u = np.asarray(u, float)
    area = np.concatenate(([0.0], np.cumsum(u[:-1] * np.diff(t_src))))
    g = np.clip(grid, t_src[0], t_src[-1])
    a = np.interp(g, t_src, area)
    # beyond the last instant the input holds its last value
    a = a + np.maximum(grid - t_src[-1], 0.0) * u[-1]
    out = np.empty(len(grid))
    out[:-1] = np.diff(a) / np.diff(grid)
    out[-1] = zoh(t_src, u, grid[-1:])[0]
    # a step over which the input holds one value is that value exactly: the difference of the
    # running area is not (a constant duty read as 716 changes of 1e-16: a step from rest taken
    # for an input that varies between its samples)
    run = np.concatenate(([0], np.cumsum(u[1:] != u[:-1])))
    first = np.clip(np.searchsorted(t_src, grid[:-1], side="right") - 1, 0, len(u) - 1)
    last = np.clip(np.searchsorted(t_src, grid[1:], side="left") - 1, 0, len(u) - 1)
    one = run[first] == run[np.maximum(last, first)]
    out[:-1][one] = u[first[one]]
    return out


#: equal parts of each grid sample over which a loop-timed log's input is held from its own
#: instants (:func:`within_samples`): an input edge is placed to within dt / WITHIN_PARTS. The
#: mean over the whole sample is exact for the input's integral but not through a dead zone,
#: which zeroes every blend of two levels below it (duty steps of 2.7 V through a 2.65 V dead
#: zone: each start delayed by the blended edge sample, and a fit moved the dead zone there)
WITHIN_PARTS = 16
#: largest difference between a sample's held mean and the mean of its parts still taken as the
#: same input [relative to the input's range]: more, the log's input was changed after reading
WITHIN_RTOL = 1e-9


def within_samples(res: Resampling, t: np.ndarray, u: np.ndarray,
                   parts: int = WITHIN_PARTS) -> np.ndarray | None:
    """A loop-timed log's input inside each sample: the input held from its logged instants
    (``res``, file time) as the means over ``parts`` equal parts of each sample of the log's
    grid ``t`` [s, log time: ``res.grid[0]`` at 0], length ``len(t) * parts``.

    None where the samples' held means are the input already (no logged instant inside a
    sample), or where they are not ``u`` (a log cut or changed after reading: its grid is no
    longer the resampling's)."""
    if len(res.inputs) != 1 or len(t) < 2:
        return None
    (src,) = res.inputs.values()
    u = np.asarray(u, float)
    n = len(t)
    dt = float((t[-1] - t[0]) / (n - 1))
    edges = res.grid[0] + t[0] + dt / parts * np.arange(n * parts + 1)
    fine = held_mean(res.t_file, src, edges)[:-1]
    fine[(n - 1) * parts:] = u[-1]  # the last sample: the value held at its instant
    per = fine.reshape(n, parts)
    scale = max(float(np.ptp(u)), float(np.abs(u).max()), 1e-300)
    if not np.all(np.abs(per.mean(axis=1) - u) <= WITHIN_RTOL * scale):
        return None
    if np.all(np.abs(per - per[:, :1]) <= WITHIN_RTOL * scale):  # (an edge 1e-16 s off one)
        return None
    fine.flags.writeable = False
    return fine


def zoh(t_src: np.ndarray, u: np.ndarray, at: np.ndarray) -> np.ndarray:
    """The value held from the last instant of ``t_src`` at or before each of ``at`` (the first
    value before the first instant)."""
    k = np.searchsorted(t_src, at, side="right") - 1
    return np.asarray(u)[np.clip(k, 0, len(u) - 1)]


def interpolated(t_src: np.ndarray, y: np.ndarray, at: np.ndarray) -> np.ndarray:
    """A measurement ``y`` taken at ``t_src``, linearly interpolated at ``at``."""
    return np.interp(at, t_src, np.asarray(y, float))


def loop_note(clock: Clock, n_rows: int, measured: list[str]) -> str:
    """The one line a loop-timed log's reading prints."""
    lo, hi = clock.spread
    merged_rows = "" if clock.groups is None else \
        f"; {n_rows - len(clock.groups)} repeated time stamp(s) merged"
    what = f", {', '.join(measured)} interpolated linearly" if measured else ""
    return (f"loop-timed samples ({_dt_text(lo)} to {_dt_text(hi)} apart): put on a uniform "
            f"{_dt_text(clock.period)} grid, the input held from each logged instant"
            f"{what}{merged_rows} (docs/io.md, 'Clocks')")


def resample_columns(t: np.ndarray, data: dict[str, np.ndarray], clock: Clock,
                     extra: dict[str, np.ndarray] | None = None):
    """Columns logged at instants ``t`` (one time column, rows possibly repeating a stamp) on
    ``clock.grid``: inputs held (:func:`held_mean`), the rest interpolated. Returns the columns,
    the extra columns, and the :class:`Resampling`."""
    t_rows = np.asarray(t, float)
    if clock.groups is not None:
        t = t_rows[clock.groups]
    out, measured = {}, []
    for name, x in data.items():
        held = name in INPUTS
        xs = merged(x, clock.groups, held) if clock.groups is not None else x
        if held:
            out[name] = held_mean(t, xs, clock.grid)
        else:
            out[name] = interpolated(t, xs, clock.grid)
            measured.append(name)
    ext = {}
    for name, x in (extra or {}).items():
        xs = merged(x, clock.groups, False) if clock.groups is not None else x
        ext[name] = interpolated(t, xs, clock.grid)
    inputs = {k: np.asarray(v, float) for k, v in data.items() if k in INPUTS}
    note = loop_note(clock, len(t_rows), measured)
    return out, ext, Resampling(t_rows, inputs, clock.grid, note, measured)
