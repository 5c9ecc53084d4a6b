"""fit-electrical: blocked-rotor current steps -> R [ohm], L [H] (paper section III-A).

With the rotor held, the armature is an RL circuit (paper eq. 3): after a voltage step of
amplitude dV at t0 the current is ``i(t) = i_before + dV/R (1 - exp(-(t - t0 - d)/tau_e))``,
tau_e = L/R, with d a dead time (drive or sensor latency, 0 for an ideal rig).

Per log: the step is found in the voltage column; Strejc's method gives the gain Ke and tau_e
(and says whether the response looks of higher order than one); least squares refines gain,
time constant and dead time. Jointly over all logs: one tau_e, one dead time, and the steady
current on a line ``i_ss = V/R + c`` across amplitudes: the slope gives R; a non-zero intercept c
is a brush drop (c = -vb/R) or a current-sensor offset, and is reported, not averaged into R.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.results import (
    Estimate,
    FitStats,
    ResultProtocol,
    bounded,
    format_estimates,
    write_estimate,
)
from pmdcid.identify.freerun import fit_free_running, loaded_current, rotor_turns
from pmdcid.identify.steps import (
    StepInfo,
    find_steps,
    first_order,
    fit_first_order,
    lsq,
    residual_std,
    strejc,
)
from pmdcid.model import Model

STAGE = "fit-electrical"
#: tau_e below this many sample periods: L not identifiable from that log
MIN_TAU_SAMPLES = 3.0
#: the words beside an L (and L/R) these logs only bound
L_CAVEAT = (f"not identifiable from these logs, L/R under {MIN_TAU_SAMPLES:g} sample periods: "
            "record blocked-rotor steps sampled faster")
#: an intercept is reported as significant beyond this many standard errors
INTERCEPT_SIGMAS = 3.0
#: tau_e plus dead time must be under this fraction of the log after the step
SETTLE_FRACTION = 0.25


def paper_electrical(ke: float, tau_e: float) -> tuple[float, float]:
    """The paper's eqs. (10)-(11): R = 1/Ke [ohm], L = tau_e R [H] (Ke [A/V], tau_e [s])."""
    r = 1.0 / ke
    return r, tau_e * r


@dataclass
class StepReport:
    """One log's first-order fit: amplitude [V], Ke [A/V], tau_e [s], dead time [s], Strejc."""

    path: str
    amplitude: float
    v_after: float
    i_ss: float
    ke: float
    ke_se: float
    tau: float
    tau_se: float
    dead_time: float
    strejc_ke: float
    strejc_tau: float
    strejc_order: int
    sigma: float


@dataclass
class ElectricalResult(ResultProtocol):
    """R, L (and tau_e, the line's intercept) with standard errors; per-log fits; warnings."""

    estimates: dict[str, Estimate]
    steps: list[StepReport]
    stats: FitStats
    warnings: list[str] = field(default_factory=list)

    def apply(self, model: Model) -> None:
        """Write R and L into ``model`` (stage 'fit-electrical'); other parameters are kept."""
        for name in ("R", "L"):
            write_estimate(model, self.estimates[name], STAGE)
        fits = model.extra.setdefault("fits", {})
        fits[STAGE] = {
            "logs": [s.path for s in self.steps],
            "tau_e": self.estimates["tau_e"].value,
            "intercept_A": self.estimates["i0"].value,
            "intercept_stderr_A": _finite(self.estimates["i0"].stderr),
            "ndata": self.stats.ndata, "redchi": self.stats.redchi,
        }
        self._keep_lumped(model)

    def table(self) -> str:
        lines = ["fit-electrical: blocked-rotor steps (Strejc, then least squares)", ""]
        lines.append(f"{'log':<28} {'step V':>7} {'Ke A/V':>10} {'tau_e ms':>9} "
                     f"{'dead ms':>8} {'Strejc':>7}")
        for s in self.steps:
            name = s.path if len(s.path) <= 28 else "..." + s.path[-25:]
            lines.append(f"{name:<28} {s.amplitude:7.3g} {s.ke:10.5g} {1e3 * s.tau:9.4g} "
                         f"{1e3 * s.dead_time:8.3g} {'n=' + str(s.strejc_order):>7}")
        lines.append("")
        lines.append("joint fit (shared tau_e and dead time; i_ss = V/R + i0 across amplitudes):")
        lines += format_estimates([self.estimates[k] for k in ("R", "L", "tau_e", "i0")])
        lines.append(f"reduced chi-square {self.stats.redchi:.3g} ({self.stats.ndata} samples)")
        return "\n".join(lines)


def _finite(x: float):
    return x if math.isfinite(x) else None


def _fit_one(log, step: StepInfo) -> tuple[StepReport, object]:
    t = log.t
    i = np.asarray(log["i"], float)
    st = strejc(t, i, step)
    cf = fit_first_order(t, i, step, st)
    du = step.amplitude
    rep = StepReport(log.path, du, step.after, cf["y0"] + cf["dy"], cf["dy"] / du,
                     cf.se("dy") / abs(du), cf["tau"], cf.se("tau"), cf["d"], st.gain, st.tau,
                     st.order, residual_std(t, i, step))
    return rep, cf


def classify(log) -> str:
    """'free' when the rotor turns in ``log`` (its speed moves), else 'blocked'.

    A log without a speed whose current overshoots and falls back after the step, as a motor
    speeding up does, cannot give R, L (back-EMF unknown): :class:`FitError`, one line.
    """
    log.require("v", "i", purpose="fit-electrical (voltage and armature current)")
    if log.has("omega"):
        return "free" if rotor_turns(log["omega"]) else "blocked"
    step = find_steps(log.t, log.u, log.path)[0]
    turns, peak, final = loaded_current(log["i"][:step.end], step.onset)
    if turns:
        raise FitError(f"the rotor turns (the current rises by {peak:.3g} A after the step, then "
                       f"falls to {final:.3g} A, as a motor speeding up does) and the log has no "
                       "speed: give a speed or angle column (free-running fit) or a "
                       "blocked-rotor log", log.path)
    return "blocked"


def fit_electrical(logs, model: Model | None = None):
    """Fit R [ohm] and L [H] (and ke [V s/rad] when the rotor turns) to logs with ``v``, ``i``.

    Blocked-rotor logs (one step each, rotor still): :class:`ElectricalResult` by the Strejc and
    first-order fit. When any log shows the rotor turning (a speed that moves), every log goes
    into the free-running regression of :mod:`.freerun` (:class:`FreeRunResult`; a blocked log
    enters it with zero speed). ``model`` is read only for an earlier L (kept when the free-running
    logs do not resolve L). Raises :class:`FitError` when no log holds what the stage needs.
    """
    if not logs:
        raise FitError("fit-electrical needs at least one blocked-rotor or free-running log")
    kinds = [classify(log) for log in logs]
    if "free" in kinds:
        return fit_free_running(logs, model)
    warns: list[str] = []
    reps, steps, used = [], [], []
    for log in logs:
        found = find_steps(log.t, log.u, log.path)
        step = found[0]
        if len(found) > 1 or step.end < log.n:  # the first step, up to the next change
            if len(found) > 1:
                warns.append(f"{log.path}: {len(found)} steps in the input: the first (to "
                             f"{step.after:.3g} V at t = {step.t0:.4g} s) is used")
            log = _head(log, step.end)
        rep, _ = _fit_one(log, step)
        after = float(log.t[-1] - step.t0)
        if not (rep.tau + rep.dead_time < SETTLE_FRACTION * after):
            raise FitError(f"the log ends {after:.3g} s after the step, before the current "
                           f"settles (tau_e about {rep.tau:.3g} s): record longer", log.path)
        if rep.strejc_order > 1:
            warns.append(f"{log.path}: Strejc's method says the current response is of order "
                         f"{rep.strejc_order}, not 1 (an extra lag: drive, current filter or "
                         "eddy currents); the first-order R, L are approximate")
        if rep.tau < MIN_TAU_SAMPLES * log.dt:
            warns.append(f"{log.path}: tau_e = {rep.tau * 1e3:.3g} ms is under "
                         f"{MIN_TAU_SAMPLES:g} sample periods ({log.dt * 1e3:.3g} ms): L is not "
                         "identifiable from this log (sample faster)")
        reps.append(rep)
        steps.append(step)
        used.append(log)
    return _joint(used, steps, reps, warns)


def _head(log, end: int):
    """The log's first ``end`` samples (a step's plateau ends where the input changes again)."""
    return replace(log, t=log.t[:end], data={k: v[:end] for k, v in log.data.items()})


def _joint(logs, steps, reps, warns) -> ElectricalResult:
    n = len(logs)
    v_after = np.array([s.after for s in steps])
    distinct = len(np.unique(np.round(v_after, 6))) >= 2
    tau0 = float(np.median([r.tau for r in reps]))
    d0 = float(np.median([r.dead_time for r in reps]))
    ke = np.array([r.ke for r in reps])
    g0 = float(np.median(ke))
    c0 = 0.0
    if distinct:
        g0, c0 = np.polyfit(v_after, [r.i_ss for r in reps], 1)
    sig = []
    for log, r in zip(logs, reps, strict=True):
        scale = max(float(np.max(np.abs(log["i"]))), 1e-12)
        s = r.sigma if math.isfinite(r.sigma) and r.sigma > 0 else 1e-6 * scale
        sig.append(max(s, 1e-9 * scale))
    names = ["G", "i0", "tau", "d"] + [f"b{k}" for k in range(n)]
    x0 = [g0, c0, tau0, d0] + [float(np.median(log["i"][: s.onset]))
                               for log, s in zip(logs, steps, strict=True)]
    span = min(log.t[-1] - s.t0 for log, s in zip(logs, steps, strict=True))
    dtmin = min(log.dt for log in logs)
    lo = np.array([-np.inf, -np.inf, 0.05 * dtmin, 0.0] + [-np.inf] * n)
    hi = np.array([np.inf, np.inf, 10 * span, 0.5 * span] + [np.inf] * n)
    if not distinct:
        lo[1], hi[1] = -1e-300, 1e-300
        x0[1] = 0.0

    def resid(x):
        g, c, tau, d = x[:4]
        parts = []
        for k, (log, s) in enumerate(zip(logs, steps, strict=True)):
            b = x[4 + k]
            model = first_order(log.t - s.t0, b, g * s.after + c - b, tau, d)
            parts.append((model - log["i"]) / sig[k])
        return np.concatenate(parts)

    ends = np.cumsum([len(log["i"]) for log in logs])
    cf = lsq(resid, x0, lo, hi, names,
             segments=[(k, int(e - len(log["i"])), int(e)) for k, (log, e)
                       in enumerate(zip(logs, ends, strict=True))])
    g, c, tau = cf["G"], cf["i0"], cf["tau"]
    if g <= 0:
        raise FitError("blocked-rotor fit gives a non-positive conductance: check the sign of the "
                       "current column against the voltage (map it with -c i=SRC*-1)",
                       ", ".join(dict.fromkeys(log.path for log in logs)))
    r = 1.0 / g
    r_se = cf.se("G") / g**2
    L = tau * r
    L_se = L * math.hypot(cf.se("tau") / tau, r_se / r)
    est = {"R": Estimate("R", r, r_se, "ohm"), "L": Estimate("L", L, L_se, "H"),
           "tau_e": Estimate("tau_e", tau, cf.se("tau"), "s"),
           "i0": Estimate("i0", c, cf.se("i0") if distinct else math.nan, "A", vary=distinct)}
    top = MIN_TAU_SAMPLES * dtmin
    if tau < top:
        # the rise ends within a few samples, and a step between two samples looks faster: the
        # data only bound tau_e to [0, 3 dt], not the fit's error (small, or huge where a rise
        # within one sample leaves the fit degenerate)
        est["tau_e"] = bounded("tau_e", 0.0, top, "s", L_CAVEAT, tau)
        est["L"] = bounded("L", 0.0, top * r, "H", L_CAVEAT, L)
    chisqr = float(cf.sigma**2 * max(cf.ndata - len(x0), 1))
    stats = FitStats(cf.ndata, len(x0) - (0 if distinct else 1), chisqr, 0, cf.success)
    if distinct and abs(c) > INTERCEPT_SIGMAS * cf.se("i0"):
        warns.append(
            f"steady current against voltage has a non-zero intercept i0 = {c * 1e3:.3g} "
            f"± {cf.se('i0') * 1e3:.2g} mA: a brush drop (about {-c * r:.3g} V) or a current "
            "sensor offset; R is taken from the slope, not the ratio i/V")
    if not distinct:
        warns.append("all logs step to the same voltage: the intercept of i_ss against V (brush "
                     "drop, sensor offset) cannot be checked; R = V/i_ss assumes it is zero")
    if tau < MIN_TAU_SAMPLES * dtmin:
        warns.append(f"joint tau_e = {tau * 1e3:.3g} ms is under {MIN_TAU_SAMPLES:g} sample "
                     "periods: L is not identifiable from these logs (written as the interval "
                     f"that spreads from 0 to {MIN_TAU_SAMPLES:g} sample periods of L/R, not "
                     "as a value with a standard error)")
    return ElectricalResult(est, reps, stats, warns)
