"""Residuals of a model on logs: errors per log and signal, whiteness, the effects' context."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import chdtrc  # scipy.stats.chi2.sf without scipy.stats' 0.4 s import

from pmdcid.fit.problem import Problem
from pmdcid.fit.results import nrmse
from pmdcid.io.derive import log_cutoff
from pmdcid.model.residual import LogResidual, ResidualContext
from pmdcid.simulate import SimResult

#: residual std over the noise level beyond which a channel shows structure ...
STRUCTURE_RATIO = 1.5
#: ... and the Ljung-Box p-value below which it is clearly not white
WHITENESS_P = 1e-6
LJUNG_BOX_LAGS = 20


def error_table(problem: Problem, sims: list[SimResult]) -> list[dict[str, float]]:
    """Per log: signal -> NRMSE (RMS error / std of the measurement) at the full sample rate."""
    out = []
    for k, log in enumerate(problem.logs):
        row = {}
        for s in log.compared_signals():
            row[s] = nrmse(sims[k].get(s), np.asarray(log[s], float))
        out.append(row)
    return out


def pooled(table: list[dict[str, float]]) -> dict[str, float | None]:
    """Mean NRMSE over the logs carrying each signal (``omega_nrmse``, ``theta_nrmse``, ...)."""
    out: dict[str, float | None] = {}
    for s in ("omega", "theta", "i"):
        v = [r[s] for r in table if s in r and math.isfinite(r[s])]
        out[f"{s}_nrmse"] = float(np.mean(v)) if v else None
    return out


@dataclass
class Whiteness:
    """One channel's residual: std over noise level, lag-1 autocorrelation, Ljung-Box p-value."""

    log: int
    signal: str
    ratio: float
    rho1: float
    p_value: float

    @property
    def structured(self) -> bool:
        return self.ratio > STRUCTURE_RATIO and self.p_value < WHITENESS_P


def ljung_box(r: np.ndarray, lags: int = LJUNG_BOX_LAGS) -> tuple[float, float]:
    """(lag-1 autocorrelation, Ljung-Box p-value) of a residual sequence."""
    r = r - np.mean(r)
    n = len(r)
    den = float(np.dot(r, r))
    if n <= lags + 2 or den <= 0:
        return 0.0, 1.0
    rho = np.array([np.dot(r[:-k], r[k:]) / den for k in range(1, lags + 1)])
    q = n * (n + 2) * float(np.sum(rho**2 / (n - np.arange(1, lags + 1))))
    return float(rho[0]), float(chdtrc(lags, q))


def whiteness(problem: Problem, sims: list[SimResult]) -> list[Whiteness]:
    """Whiteness of the current and speed residuals (the angle integrates, it is never white)."""
    out = []
    for ch in problem.channels:
        if ch.signal == "theta":
            continue  # the angle integrates: never white
        r = problem.residual(sims, ch)
        if ch.derived_cutoff is not None:
            # a derived speed's noise is filtered, correlated over about 1/(2 fc): test the
            # residual at that spacing, where filtered white noise is nearly white again
            log = problem.logs[ch.log]
            step = ch.rows.step * log.dt if len(ch.meas) > 1 else log.dt
            r = r[:: max(1, int(math.ceil(1.0 / (2.0 * ch.derived_cutoff * step))))]
        r = r[np.isfinite(r)]
        if len(r) < 30:
            continue
        rho1, p = ljung_box(r)
        out.append(Whiteness(ch.log, ch.signal, float(np.std(r)) / ch.sigma, rho1, p))
    return out


def context(problem: Problem, vals: dict[str, float], sims: list[SimResult]) -> ResidualContext:
    """The effects' view of the residual (fit part only; held-out samples NaN), as the deficit
    measured - simulated: what a missing effect must add (the probes and guesses of
    each :mod:`pmdcid.model.effects` module read it so); the fits' residual is its negative."""
    logs = []
    for k, log in enumerate(problem.logs):
        fit = problem.fit_mask(k)
        resid = {}
        for s in ("i", "omega", "theta"):
            if log.compares(s):
                r = np.asarray(log[s], float) - sims[k].get(s)
                resid[s] = np.where(fit, r, np.nan)
        blocked = problem.blocked[k]
        logs.append(LogResidual(
            log.t, log.u, log.drive == "tau", blocked,
            None if blocked or not log.has("omega") else np.asarray(log["omega"], float),
            None if blocked or not log.has("theta") else np.asarray(log["theta"], float),
            sims[k].omega_true, resid,
            log_cutoff(log) if "omega" in log.derived else math.inf))
    speeds = [np.abs(lg.omega) for lg in logs if lg.omega is not None]
    speed = float(np.percentile(np.concatenate(speeds), 95)) if speeds else 0.0
    if not speed > 0:
        speed = max(float(max(np.max(np.abs(s.omega_true)) for s in sims)), 1.0)
    bv, bc, dz = (max(vals.get(n, 0.0), 0.0) for n in ("bv", "bc", "dz"))
    torque = max(bc + bv * speed, dz)
    if not torque > 0:
        torque = max(vals.get("J", 1.0) * speed, 1e-12)
    volts = [float(np.max(np.abs(lg.u))) for lg in logs if not lg.torque_driven]
    return ResidualContext(dict(vals), logs, torque, speed, max(volts) if volts else 0.0,
                           min(lg.dt for lg in logs))


def typical_scales(ctx: ResidualContext) -> dict[str, float]:
    """Typical size of every parameter (SI) from the context's scales, by unit.

    Used to scale refits of parameters that start at 0.
    """
    from pmdcid.model.effects import effect_param_specs
    from pmdcid.model.spec import BASE_PARAMS

    t, w = ctx.torque_scale, ctx.speed_scale
    v = max(ctx.voltage_scale, 1e-3)
    by_unit = {"N m": t, "rad/s": w, "V": v, "s": 10 * ctx.dt, "N m s/rad": t / w,
               "N m s^2/rad^2": t / w**2, "V s/rad": v / w, "rad": 1.0, "1": 1.0}
    specs = {**BASE_PARAMS, **effect_param_specs()}
    return {n: by_unit.get(sp.unit, 1.0) for n, sp in specs.items()}


__all__ = ["Whiteness", "context", "drift_notes", "drift_problem", "error_table", "ljung_box",
           "pooled", "typical_scales",
           "whiteness"]


#: base parameters whose stability over time is checked, and the size of a change that is noted
DRIFT_PARAMS = ("J", "bv", "bc")
DRIFT_REL = 0.10
DRIFT_Z = 2.0


def drift_notes(problem: Problem, vals: dict[str, float], max_nfev: int = 40) -> list[str]:
    """Notes on base parameters that differ between the fit part (the first ``split`` of each
    log) and the held-out rest, each refitted alone from ``vals``: a change of at least
    :data:`DRIFT_REL` and :data:`DRIFT_Z` standard errors of the difference (the standard error
    allowing for correlated residuals, scaled from all the data to the two parts). A friction
    that drifts (warm-up, wear) is no catalogue effect, and a time-invariant effect may be
    credited in its place: this says where to look."""
    free = [n for n in DRIFT_PARAMS if n in vals and vals[n] > 0]
    if not free or problem.count("held") == 0 or problem.count("fit") == 0:
        return []
    first = problem.fit(vals, free, "fit", max_nfev=max_nfev)
    last = problem.fit(vals, free, "held", max_nfev=max_nfev)
    se, _ = problem.correlated_stderr(vals, free)
    n_all = problem.count("all")
    # var(a - b) = var_all * (N/N_fit + N/N_held): each part has a share of the evidence
    scale = math.sqrt(n_all / problem.count("fit") + n_all / problem.count("held"))
    notes = []
    parts = ("the earlier repeats and the last one" if problem.held_logs
             else "the first part of the logs and the rest")
    for name in free:
        a, b = first.values[name], last.values[name]
        sd = se.get(name, math.nan) * scale
        rel = (b - a) / a if a else math.nan
        if abs(rel) >= DRIFT_REL and math.isfinite(sd) and sd > 0 and abs(b - a) / sd >= DRIFT_Z:
            notes.append(f"{name} differs by {100 * rel:+.0f} % between {parts} "
                         f"({abs(b - a) / sd:.1f} standard errors): it may "
                         "drift over time (warm-up, wear), which no catalogue effect represents "
                         "and a time-invariant effect may imitate; fit parts of the log "
                         "separately to see it")
    return notes


#: two parts of a log have similar excitation when the std of the input and of the measured
#: speed, and the mean |speed|, agree within this factor
SIMILAR = 1.5


def _similar(a: np.ndarray, b: np.ndarray) -> bool:
    sa, sb = float(np.std(a)), float(np.std(b))
    ma, mb = float(np.mean(np.abs(a))), float(np.mean(np.abs(b)))
    return all(x > 0 and y > 0 and max(x / y, y / x) <= SIMILAR
               for x, y in ((sa, sb), (ma, mb)))


def drift_problem(problem: Problem) -> Problem | None:
    """The data on which drift can show, as a problem whose fit and held-out parts are
    comparable: the repeats of a protocol (runs at different times), else the logs split in time
    whose two parts have similar excitation (a periodic input; never a step's transient against
    its plateau). None when there are none."""
    if problem.held_logs:
        keep = [k for k, p in enumerate(problem.plan) if p in ("fit", "held")]
    else:
        keep = []
        for k, log in enumerate(problem.logs):
            if problem.blocked[k] or not log.has("omega"):
                continue
            m = problem.fit_mask(k)
            w, u = np.asarray(log["omega"], float), np.asarray(log.u, float)
            if m.any() and (~m).any() and _similar(w[m], w[~m]) and _similar(u[m], u[~m]):
                keep.append(k)
    if not keep:
        return None
    return Problem([problem.logs[k] for k in keep], problem.split,
                   plan=[problem.plan[k] for k in keep])
