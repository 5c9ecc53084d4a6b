"""fit-nonlinear: simulation-error fit of friction and dead zone (paper section III-C, automated).

The paper tunes bc and bv by hand on a triangular-input log and reads the dead zone off the
current at which the rotor starts. Here the shared kernel is simulated on each log's own input
and the parameters minimise the weighted squared error of the simulated speed and angle
(weights: each signal's noise level), jointly over all logs:

1. start: J, bv (or the paper's b), bc from fit-mechanical for voltage logs; for torque-driven
   logs (``tau`` column, R, L, km not needed) from inverse dynamics;
2. global stage: a coarse grid over the two switching parameters (bc and dz, or bc and tau0),
   then over bv, all sets of a stage simulated in one compiled batch (:mod:`.grid`);
3. local stage: trust-region least squares (:func:`pmdcid.fit.simfit.fit_simulation`) from the
   best set, with finite-difference steps wide enough to step over the kernel's event quantisation;
   standard errors and correlations from the Jacobian at the solution.

Why not a gradient method alone: the cost is piecewise smooth (breakaway and dead-zone
switching move by whole internal steps), with flat valleys where bc and dz trade off; the grid
puts the start in the right valley, least squares then converges on the smooth envelope.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.parameters import Parameters
from pmdcid.fit.priors import prior_terms, stage_priors
from pmdcid.fit.problem import noise_levels
from pmdcid.fit.results import (
    Estimate,
    ResultProtocol,
    SimFitResult,
    bounded,
    format_estimates,
    nrmse_text,
    write_estimate,
)
from pmdcid.fit.simfit import FitOptions, fit_simulation
from pmdcid.fit.solver import blas_single_thread
from pmdcid.identify.dead_zone import (
    REFIT_POINTS,
    REFIT_TOP,
    dead_zone_interval,
    refit_interval,
    refit_profile,
)
from pmdcid.identify.grid import batch_cost
from pmdcid.identify.identifiability import fit_warnings, hold_warning, require_motion
from pmdcid.identify.nonlinear_setup import (  # noqa: F401 - default_signals re-exported
    FREE_TAU,
    FREE_V,
    KNOWN_FREE,
    SIGNALS,
    check_logs,
    chosen_signals,
    default_signals,
    free_parameters,
    held_offset,
    working_model,
)
from pmdcid.identify.offset import offset_evident, offset_note
from pmdcid.identify.ramp_profile import hold_profile
from pmdcid.identify.share_valley import (
    PROBE_NFEV,
    restart_from_dips,
    share_interval,
    valley_points,
    valley_threshold,
)
from pmdcid.model import Model
from pmdcid.model.lumped import kernel_values, same_response
from pmdcid.notes import Note
from pmdcid.simulate import param_values

STAGE = "fit-nonlinear"
#: grid points per axis of the global stage
GRID_N = 7
GRID_BV = 7
#: a lumped model's tau_e is fitted down to this fraction of the sample period (at 0 the model
#: has no lag and its dead zone acts on v, pmdcid/model/lumped.py: a different model)
TAU_E_FLOOR = 0.01
#: grid of a lumped model's back-EMF share of bv (ke_share, pmdcid/model/lumped.py): its whole
#: range, each point with the J and tau_e of the same linear response (:func:`share_points`)
KE_SHARES = (0.0, 0.1, 0.25, 0.5, 0.7, 0.8, 0.85, 0.9, 0.95, 0.98, 0.99, 0.995, 0.998, 0.999, 1.0)
#: relative finite-difference steps of the local stage: the switching parameters move events by
#: whole internal steps, so their steps must span several (a torque ramp of ~1e-3 relative per
#: internal step on a slow triangle)
DIFF_STEP = {"J": 1e-3, "bv": 1e-3, "bc": 1e-2, "dz": 1e-2, "tau0": 1e-2, "tau_e": 1e-2,
             "ke_share": 1e-2}
#: a friction or offset start below this fraction of the logs' torque scale is taken as 0
#: (and the local stage starts it at 1e-3 of the scale)
ZERO_START = 1e-9
#: points of the dz profile that tests whether the dead zone is visible at all
DZ_PROFILE_N = 25
#: a dead zone must lower the chi-square by more than this fraction to count as identified
MASK_REL = 1e-3
#: J and bv are refined within this factor of their start (fit-mechanical or inverse dynamics):
#: a misspecified model (an effect not yet added) must not drive the inertia to 0, where the fit
#: is meaningless and every simulation needs thousands of internal steps
REFINE_RANGE = 10.0


@dataclass
class NonlinearResult(ResultProtocol):
    """J, bv, bc, dz (and tau0) with standard errors, correlations, per-log NRMSE, warnings."""

    estimates: dict[str, Estimate]
    fit: SimFitResult
    signals: tuple[str, ...]
    paths: list[str]
    start: dict[str, float]
    grid_best: dict[str, float]
    grid_sets: int
    seconds: float
    warnings: list[str] = field(default_factory=list)
    #: name -> the stage whose estimate entered as a prior (see :func:`stage_priors`)
    prior_from: dict[str, str] = field(default_factory=dict)
    #: closed-loop logs: which route the fit took and why (:class:`.closedfit.Route`)
    route: object = None
    #: the controller route: the logged-output fit it started from
    open_loop: object = None
    #: how many starts the logs gave (the fit ran from each, this one the lowest chi-square)
    starts: int = 1
    #: the parameters whose values in the model came from these logs (identify's joint fit):
    #: :meth:`apply` writes their estimates, one these logs do not determine included
    #: (:func:`pmdcid.identify.runners.stage_nonlinear`)
    replaces: frozenset = frozenset()

    @property
    def stats(self):
        return self.fit.stats

    @property
    def bc_dz_correlation(self) -> float:
        return self.fit.correlation("bc", "dz")

    @property
    def nrmse(self) -> list[dict[str, float]]:
        return self.fit.nrmse

    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.estimates.items()}

    def apply(self, model: Model) -> None:
        """Write the fitted parameters (stage 'fit-nonlinear'); tau0 adds ``torque_offset``."""
        for name, e in self.estimates.items():
            if name == "ramp":  # how this log's input varied, not a property of the motor
                continue
            if name == "tau0":
                model.add_effect("torque_offset")
            write_estimate(model, e, STAGE, keep=name not in self.replaces)
        fits = model.extra.setdefault("fits", {})
        r = self.bc_dz_correlation
        fits[STAGE] = {
            "logs": self.paths, "signals": list(self.signals),
            "nrmse": self.nrmse, "redchi": self.stats.redchi, "ndata": self.stats.ndata,
            "sigma": self.fit.sigma,
            "route": None if self.route is None else {"name": self.route.name,
                                                      "why": self.route.why},
            "bc_dz_correlation": r if math.isfinite(r) else None,
            "covariance": self.fit.covariance.as_dict() if self.fit.covariance else None,
            "priors": {n: {"from": s, "value": self.fit.priors[n][0],
                           "stderr": self.fit.priors[n][1]}
                       for n, s in self.prior_from.items() if n in self.fit.priors},
        }
        self._keep_lumped(model)

    def table(self) -> str:
        lines = [f"fit-nonlinear: simulation error on {', '.join(self.signals)} "
                 f"({len(self.paths)} log(s); grid {self.grid_sets} sets, then least squares)",
                 ""]
        if self.route is not None:
            lines[1:1] = [self.route.line()]
        lines += format_estimates(list(self.estimates.values()))
        if self.prior_from:
            by = {}
            for n, src in self.prior_from.items():
                by.setdefault(src, []).append(n)
            lines.append("combined with earlier estimates (Gaussian priors): " + "; ".join(
                f"{', '.join(ns)} from {src}" for src, ns in by.items()))
        cov = self.fit.covariance  # said whenever the errors are only lower bounds, too
        if cov and (cov.inflation > 1.5 or cov.lower_bound):
            lines.append(cov.describe())
        r = self.bc_dz_correlation
        if math.isfinite(r):
            lines.append(f"correlation bc-dz {r:+.3f}")
        for name in ("bc", "tau0"):
            c = self.fit.correlation("J", name)
            if name in self.estimates and math.isfinite(c) and abs(c) > 0.5:
                lines.append(f"correlation J-{name} {c:+.3f}")
        for p, e in zip(self.paths, self.nrmse, strict=True):
            errs = ", ".join(f"{k} {nrmse_text(v)}" for k, v in e.items())
            lines.append(f"NRMSE {p}: {errs}")
        s = self.stats
        lines.append(f"reduced chi-square {s.redchi:.3g} ({s.ndata} samples, {s.nfev} "
                     f"simulations in the local stage, {self.seconds:.2f} s)")
        return "\n".join(lines)


def _torque_scale(logs, vals) -> float:
    s = 0.0
    for lg, v in zip(logs, vals, strict=True):
        u = float(np.max(np.abs(lg.u)))
        s = max(s, u if lg.drive == "tau" else v["km"] * u / v["R"])
    return s if s > 0 else 1.0


def _axis(name: str, start: dict[str, float], tscale: float) -> np.ndarray:
    """Grid values of one switching parameter around its start (SI units)."""
    bc = start["bc"]
    if name == "bc":
        return (np.geomspace(bc / 3, 3 * bc, GRID_N) if bc > 0
                else np.linspace(0, 0.3 * tscale, GRID_N))
    if name == "dz":
        ref = max(start["dz"], bc)
        top = 2.0 * ref if ref > 0 else 0.3 * tscale
        return np.linspace(0.0, top, GRID_N)
    if name == "tau0":
        half = max(bc, 0.05 * tscale)
        return start["tau0"] + np.linspace(-half, half, GRID_N)
    raise ValueError(name)


def _cost(logs, base_vals, sets, signals, sigma) -> np.ndarray:
    """Weighted squared simulation error of each parameter set, summed over the logs (each
    from its measured initial state, :mod:`.initial`)."""
    from pmdcid.simulate.initial import initial_state

    total = np.zeros(len(sets))
    for k, lg in enumerate(logs):
        vl = [{**base_vals[k], **s} for s in sets]
        total += batch_cost(lg, vl, {s: sigma[k][s] for s in signals if s in sigma[k]},
                            x0=initial_state(lg, sigma[k].get("omega")))
    return total


def _grid_search(logs, base_vals, start, free, signals, sigma, tscale):
    """Coarse grid over (two switching parameters), then over bv; returns (best, nsets)."""
    best = {k: start[k] for k in free}
    sw = [n for n in ("bc", "dz", "tau0") if n in free][:2]
    nsets = 0

    def run(sets):
        return _cost(logs, base_vals, [{**best, **s} for s in sets], signals, sigma)

    def switching():
        axes = [_axis(n, start, tscale) for n in sw]
        mesh = np.meshgrid(*axes, indexing="ij")
        sets = [dict(zip(sw, vals, strict=True))
                for vals in zip(*(m.ravel() for m in mesh), strict=True)]
        sets.append({n: best[n] for n in sw})  # the start itself competes
        cost = run(sets)
        best.update(sets[int(np.argmin(cost))])
        return len(sets)

    if sw:
        nsets += switching()
    if "ke_share" in free:
        # a lumped model's back-EMF share moves where its dead zone acts (the torque per volt
        # is v - ke w): the local stage does not cross between its valleys, a grid over the
        # share and dz together does (at a share of 1 a dead zone above bc would hold every
        # steady state, so dz alone looks masked); then the switching parameters again
        dzs = list(_axis("dz", start, tscale)) + [best["dz"]] if "dz" in free else [None]
        sets = [{**lag, **({"dz": d} if d is not None else {})}
                for lag in share_points(best) for d in dzs]
        cost = run(sets)
        nsets += len(sets)
        best.update(sets[int(np.argmin(cost))])
        if sw:
            nsets += switching()
    if "bv" in free:
        sets = [{"bv": v} for v in start["bv"] * np.geomspace(1 / 1.5, 1.5, GRID_BV)]
        cost = run(sets)
        nsets += len(sets)
        best.update(sets[int(np.argmin(cost))])
    return best, nsets


def share_points(best: dict[str, float]) -> list[dict[str, float]]:
    """The back-EMF shares :data:`KE_SHARES` (and ``best``'s) to grid a lumped model's lag
    over, each with the J and tau_e that keep ``best``'s linear response
    (:func:`pmdcid.model.lumped.same_response`; J, tau_e held where ``best`` has neither).
    At fixed J the grid cannot leave the valley it starts in: the share trades with J and
    tau_e (on the paper's motor, share 0.033, a start at share 1 carries J +7.6 %,
    bench/pervolt_coverage.py)."""
    out = []
    for v in sorted({*KE_SHARES, best["ke_share"]}):
        pt = {"ke_share": v}
        if "J" in best and "tau_e" in best:
            moved = same_response(best["J"], best["tau_e"], best["bv"], best["ke_share"], v)
            if moved is None:
                continue
            pt["J"], pt["tau_e"] = moved
        out.append(pt)
    return out


def dz_profile(logs, base_vals, point, signals, sigma, ndata, n=DZ_PROFILE_N):
    """Cost along dz at ``point`` (other parameters held), dz in [0, 1.5 max(bc, dz)] [N m].

    Returns (dz values, cost, threshold, cost at ``point``): the threshold is a chi-square rise
    of 4 (two standard errors), scaled by the reduced chi-square when the fit is worse than the
    noise.
    """
    top = 1.5 * max(point.get("bc", 0.0), point.get("dz", 0.0), 1e-12)
    dzs = np.linspace(0.0, top, n)
    c = _cost(logs, base_vals, [{**point, "dz": d} for d in dzs] + [point], signals, sigma)
    return dzs, c[:-1], 4.0 * max(float(c.min()) / max(ndata, 1), 1.0), float(c[-1])


def masked_upper(dzs, cost, thr) -> float:
    """Largest dz [N m] up to which the cost stays within ``thr`` of its value at dz = 0."""
    ok = (cost - cost[0]) <= thr
    j = int(np.argmin(ok)) if not ok.all() else len(ok)
    return float(dzs[max(j - 1, 0)])


def crossing_upper(dzs, cost, thr) -> float:
    """Largest dz [N m] up to which the cost stays within ``thr`` of its value at dz = 0, the
    edge read between the profile's points by linear interpolation (the whole line when the
    cost never leaves that band)."""
    k = int(np.searchsorted(dzs, masked_upper(dzs, cost, thr), side="right"))
    if k >= len(dzs) or not math.isfinite(cost[k]):
        return float(dzs[min(k, len(dzs)) - 1])
    a, b = cost[k - 1] - cost[0], cost[k] - cost[0]
    return float(dzs[k - 1] + (dzs[k] - dzs[k - 1]) * (thr - a) / max(b - a, 1e-300))


#: the refitted dz profile's local fits: their evaluations at most
PROFILE_NFEV = 60
#: their relative finite-difference steps at least (the cost is a staircase in bc as in dz)
PROFILE_STEP = 3e-2


def _refit_at(logs, work, free, signals, sigma, opts, bounds, priors, held, dz, start):
    """The local stage with dz held at ``dz`` [N m], the other ``free`` parameters from
    ``start``: (chi-square, values), None when it fails (:func:`.dead_zone.refit_profile`)."""
    others = [k for k in free if k != "dz"]
    try:
        params = _parameters(others, start, bounds,
                             {k: max(PROFILE_STEP, DIFF_STEP.get(k, 0.0)) for k in others},
                             priors, {**held, "dz": dz})
        f = fit_simulation(logs, work, params, signals, sigma=sigma,
                           options=FitOptions(PROFILE_NFEV, noise_model=opts.noise_model))
    except FitError:
        return None
    return f.stats.chisqr, f.values()


def _check_dead_zone(logs, base_vals, best, fit, signals, sigma, ndata, fits):
    """dz checked at the fitted point: (fit, the masked interval's upper end [N m] or None when the
    logs see the dead zone, point, the refitted points across a masked interval that fit as
    well: :func:`_unmask`'s, empty without them). The grid's hint comes from its coarse bc, and
    a local stage may stop where dz = 0 (a bound) or in a side valley: if some dz on the profile
    (the others held) is clearly better, the local stage again from there. Identified only if
    the dead zone improves the fit clearly: by more than two standard errors AND 0.1 % of the
    chi-square (the kernel's event quantisation leaves wiggles of a few units of chi-square at
    the edge of a flat valley). With a lumped model's electrical lag free, a dead zone that
    profile calls masked is checked along its refitted profile (:func:`_unmask`). Not without
    the lag: the dead zone is then on the applied voltage, flat up to the smallest level driven,
    and the refitted profile's wider interval only moved the point diagnose holds dz at when it
    takes the lag later (bench/lawlag.py, 500 Hz, L/R 2 ms: J' -1.5 -> -36 of its standard
    errors on seed 10). ``fits``: (the local stage with dz held, :func:`_refit_at`; the local
    stage from a start, dz free)."""
    point = {**best, **fit.values()}
    dzs, c, thr, cfit = dz_profile(logs, base_vals, point, signals, sigma, ndata)
    if c.min() < cfit - thr:
        fit = fits[1]({**point, "dz": float(dzs[int(np.argmin(c))])})
        point = {**best, **fit.values()}
        dzs, c, thr, cfit = dz_profile(logs, base_vals, point, signals, sigma, ndata)
    masked = bool(c[0] - min(c.min(), cfit) <= max(thr, MASK_REL * min(c.min(), cfit)))
    if masked and "tau_e" in point:
        again, upper, alike = _unmask(point, thr, fits)
        if again is not None:
            return again, None, {**best, **again.values()}, []
        if upper is not None:
            return fit, upper, point, alike
    if not masked:
        return fit, None, point, []
    return fit, _held_upper(logs, base_vals, point, signals, sigma, dzs, c, thr), point, []


def _held_upper(logs, base_vals, point, signals, sigma, dzs, c, thr) -> float:
    """The masked interval's upper end [N m] on the held profile ``c`` along ``dzs``, its edge
    refined inside the next interval (17 points)."""
    upper = masked_upper(dzs, c, thr)
    if upper < dzs[-1]:
        fine = np.linspace(upper, upper + (dzs[1] - dzs[0]), 17)
        cf = _cost(logs, base_vals, [{**point, "dz": d} for d in fine], signals, sigma)
        upper = masked_upper(np.concatenate([[0.0], fine]), np.concatenate([[c[0]], cf]), thr)
    return upper


#: the back-EMF shares the refitted dead-zone profile also walks from (:func:`_unmask`), where
#: more than 0.1 from the fit's: a lumped fit of logs without current has two kinds of basin,
#: a large share with no dead zone and a small share with one, and the walk from the fit's
#: own point stays in its own (bench/pervolt_coverage.py, the paper's motor, share 0.033, dz
#: 27 % above bc: paper-steps-1k seed 3 stopped at share 0.79 with dz masked to [0, 0.21] V,
#: 15 chi-square units above the basin at share 0.04 with dz 0.3-1 V, J +4.7 % at 2.2 of its
#: standard errors; from both ends, J +0.3 %. Over the four paper-* cases of 20 seeds, dz
#: (its value or its interval) held the truth in 10, 16, 15, 15 -> 18, 18, 20, 16 and J' in 9,
#: 10, 12, 11 -> 11, 10, 12, 11)
UNMASK_SHARES = (0.05, 0.95)


def _unmask(point, thr, fits):
    """A dead zone the held profile calls masked, checked along its profile likelihood (the
    other free parameters re-minimised at each dz, :func:`.dead_zone.refit_profile`, from 0 to
    :data:`.dead_zone.REFIT_TOP` x max(bc, dz)). The held profile cannot follow the ridge along
    which dz, the back-EMF share and bc trade: on bench/lawlag.py's motors (L/R 4 ms, 1 kHz,
    seed 3) it called dz masked while a dead zone 1.6 x bc fitted clearly better. The walk also
    starts from the point moved along its share's valley to each of :data:`UNMASK_SHARES`
    (with no dead zone), the lower cost at each dz kept. When some dz
    fits better than dz = 0 by more than ``thr`` and 0.1 % of the chi-square, the local stage
    again from there, dz free: (that fit, None, []); else (None, the masked interval's upper
    end read on that profile, :func:`crossing_upper`, the profile's refitted points inside
    the interval); (None, None, []) when dz = 0 or no point of the profile could be fitted
    (the held profile's reading stands)."""
    top = REFIT_TOP * max(point.get("bc", 0.0), point.get("dz", 0.0), 1e-12)
    dzs = np.linspace(0.0, top, REFIT_POINTS)
    c, vals = refit_profile(fits[0], point, dzs)
    for other in valley_points(point, UNMASK_SHARES) if "ke_share" in point else ():
        if abs(other["ke_share"] - point["ke_share"]) <= 0.1:
            continue
        co, vo = refit_profile(fits[0], {**other, "dz": 0.0}, dzs)
        better = co < c
        c = np.where(better, co, c)
        vals = [b if w else a for a, b, w in zip(vals, vo, better, strict=True)]
    low = float(c.min())
    if not math.isfinite(c[0]) or not math.isfinite(low):
        return None, None, []
    if c[0] - low <= max(thr, MASK_REL * low):
        return _masked_profile(dzs, c, vals, thr)
    k = int(np.argmin(c))
    try:
        return fits[1]({**point, **vals[k], "dz": float(dzs[k])}), None, []
    except FitError:
        return _masked_profile(dzs, c, vals, thr)


def _masked_profile(dzs, c, vals, thr):
    """(None, the masked interval's upper end, the profile's refitted points inside it)."""
    upper = crossing_upper(dzs, c, thr)
    return None, upper, [{**v, "dz": float(d)} for d, v in zip(dzs, vals, strict=True)
                         if v is not None and d <= upper]


def _chisqr_and_J(logs, work, free, signals, start, sigma, max_nfev, bounds, prior,
                  ramp: float) -> tuple[float, float]:
    """The local fit with the input read at ``ramp`` between samples: (chi-square, J)."""
    held = {"ramp": ramp}
    params = _parameters(free, start, bounds, DIFF_STEP, prior_terms(prior), held)
    opts = FitOptions(max_nfev)
    f = fit_simulation(logs, work, params, signals, sigma=sigma, options=opts)
    f = _polish(logs, work, free, signals, f, sigma, opts, bounds, prior_terms(prior), held)
    return f.stats.chisqr, f.estimates["J"].value if "J" in f.estimates else 0.0


def _parameters(free, start, bounds, steps, priors, held: dict[str, float]) -> Parameters:
    """The local stage's parameters: ``free`` from ``start``, the input reading ``held``."""
    params = Parameters.of(free, start, bounds, steps, priors)
    for n, v in held.items():
        params.fix(n, v)
    return params


#: relative finite-difference steps of the polishing fits (:func:`_polish`)
POLISH_STEPS = (3e-2, 1e-1)


def _polish(logs, work, free, signals, fit, sigma, opts, bounds, priors, held, wide=False):
    """Local fits again from the solution with wider finite-difference steps
    (:data:`POLISH_STEPS`): on a lumped model with an electrical lag (tau_e, ke_share free) the
    lowest chi-square kept; elsewhere only with ``wide`` (the stage's own local stage, not the
    ramp profile's), kept where lower than ``fit``'s by more than two standard errors' rise
    (:func:`.share_valley.valley_threshold`; the wider step tried only after the first was
    kept), else ``fit`` as it is: one more local fit where the first had stopped well.

    The dead zone's events move with tau_e and ke_share on the scale of an internal step,
    and the first local stage stops on that staircase: measured on voltage + speed logs of
    motors with L/R = 2-4 ms at 0.5-1 kHz (bench/lumped_coverage.py), it stopped hundreds of
    chi-square units above the truth's with J 3 % and tau_e 7 % off; polished, below it.
    The SI model's cost is a staircase in J and bv too (every stick and breakaway moves by
    whole internal steps with them): on a 2 kHz rig with current logged (steps, steps while
    turning, a triangle; docs/identification.md, "A joint fit stopped on the staircase") the
    cost jumps by ~1000 units (3 % of it) between bv's 1e-4 steps, the local stage's
    forward differences over 1e-3 read those jumps as its slope, and its trust region shrank
    to nothing (scipy's xtol) across a valley along which the cost still fell by half: the
    joint fit stopped at bv -16 %, bc +7 % (8 of their standard errors), reduced chi-square
    2.48; polished, 1.24 (the same fit started at the truth: 1.26)."""
    lumped = "tau_e" in free
    if not (lumped or wide):
        return fit
    top = fit.stats.chisqr - (0.0 if lumped else valley_threshold(fit))
    best = fit
    for step in POLISH_STEPS:
        try:
            params = _parameters(free, best.values(), bounds,
                                 {k: max(step, DIFF_STEP.get(k, 0.0)) for k in free}, priors,
                                 held)
            f = fit_simulation(logs, work, params, signals, sigma=sigma, options=opts)
        except FitError:
            continue
        if f.stats.chisqr < min(top, best.stats.chisqr):
            best = f
        elif not lumped:  # no clear drop at this step: the wider one is not tried
            break
    return best


#: the inertia scan's steps [standard errors of J] and the chi-square drop that restarts the
#: local stage (:func:`_scan_inertia`)
SCAN_SE = (-4.0, -3.0, -2.0, -1.5, -1.0, -0.5, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
SCAN_DROP = 2.0
#: scans and restarts at most, while one still finds a clearly lower point
SCAN_ROUNDS = 3


def _scan_inertia(logs, work, free, signals, fit, sigma, opts, bounds, priors, held,
                  base_vals):
    """The local stage again from a clearly lower point of the cost along J alone (others
    held, :data:`SCAN_SE` standard errors) or, on a lumped model with its lag free, along
    every parameter's profile line (:func:`_profile_lines`), else ``fit`` as it is. The
    stick-slip cost has kinks where a local stage can stop short of the minimum in J: on
    bench/stderr_coverage.py's paper motor (seeds 900-919) 3 of 20 joint fits stopped 1.8-2.6
    standard errors off J's minimum (seed 909: the cost 5.8 lower 2 standard errors further);
    restarted, J fell within 2 standard errors of the truth in 17 of 20 seeds (15 before), the
    RMS of (J - truth)/stderr 1.10 (1.40)."""
    e = fit.estimates.get("J")
    if e is None or not (math.isfinite(e.stderr) and e.stderr > 0):
        return fit
    pt = {k: fit.estimates[k].value for k in free}
    sets = [pt] + [{**pt, "J": e.value + k * e.stderr} for k in SCAN_SE]
    sets += [s for s in _profile_lines(fit, SCAN_SE) if _inside(s, bounds)]
    c = np.nan_to_num(_cost(logs, base_vals, sets, signals, sigma), nan=np.inf)
    if not c[1:].min() < c[0] - SCAN_DROP:
        return fit
    try:
        params = _parameters(free, sets[1 + int(np.argmin(c[1:]))], bounds, DIFF_STEP, priors,
                             held)
        f = fit_simulation(logs, work, params, signals, sigma=sigma, options=opts)
    except FitError:
        return fit
    return f if f.stats.chisqr < fit.stats.chisqr else fit


def _profile_lines(fit, steps) -> list[dict[str, float]]:
    """Points along each fitted parameter's profile direction in the covariance (the others
    following their regression on it), ``steps`` of its standard errors each way: the lines
    :func:`secant_errors` reads the cost's rise on, and a lumped model's (tau_e free) lines
    :func:`_scan_inertia` restarts from. Empty where a standard error is not finite and
    positive. The lumped model's cost is rough on the scale of an internal step (the dead
    zone's events move with tau_e, ke_share and dz), and a local stage stops where it starts
    to rise: on bench/lawlag.py's hobby motor (1 kHz, L/R 2 ms, seed 3's motor, a noise record
    of eight at the fit's own internal step) it stopped with bv' 5.6 standard errors low, the
    cost 4.4 lower one standard error along bv's line."""
    free = list(fit.estimates)
    se = np.array([fit.estimates[k].stderr for k in free])
    x = np.array([fit.estimates[k].value for k in free])
    if "tau_e" not in free or not np.all(np.isfinite(se) & (se > 0)):
        return []
    corr = np.array([[1.0 if a == b else fit.correlation(a, b) for b in free] for a in free])
    cov = np.nan_to_num(corr) * np.outer(se, se)
    return [dict(zip(free, x + cov[:, j] / cov[j, j] * k * se[j], strict=True))
            for j in range(len(free)) for k in steps]


#: the fitted parameters a scan's point may not take below 0
NONNEGATIVE = ("J", "bv", "bc", "dz", "tau_e", "ke_share", "fs", "ws", "bq")


def _limits(name: str, bounds: dict) -> tuple[float, float]:
    """(lower, upper) a scan's point may take for parameter ``name``: its ``bounds``, else 0
    below for the :data:`NONNEGATIVE` ones; a back-EMF share at most 1 whatever they say."""
    lo, hi = bounds.get(name, (0.0 if name in NONNEGATIVE else -math.inf, math.inf))
    return (lo, min(hi, 1.0)) if name == "ke_share" else (lo, hi)


def _inside(point: dict[str, float], bounds: dict) -> bool:
    """Whether ``point`` lies within ``bounds`` and the physical region (:func:`_limits`)."""
    return all(lo <= v <= hi for k, v in point.items() for lo, hi in [_limits(k, bounds)])


def _valley_restart(logs, work, free, signals, fit, sigma, opts, bounds, priors, held,
                    base_vals):
    """A lumped model with its electrical lag free (J, tau_e, ke_share, bv; else ``fit`` as
    it is): the local stage again from the back-EMF share's other dips along its valley of
    equal linear response (:func:`.share_valley.restart_from_dips`), kept where its
    chi-square is lower than ``fit``'s by more than two standard errors' rise
    (:func:`.share_valley.valley_threshold`); each start first probed for
    :data:`~.share_valley.PROBE_NFEV` evaluations and run on only where that probe is already
    so much lower (:func:`.share_valley.probed`). The share trades with J and tau_e there, only
    the friction and the dead zone telling its points apart, and the local stage stops in
    any dip of that staircase (diagnose restarts its final fit the same way,
    :mod:`pmdcid.diagnose.lagvalley`)."""
    def refit(start, options=opts):
        try:
            return fit_simulation(logs, work, _parameters(free, {**point, **start}, bounds,
                                                          DIFF_STEP, priors, held),
                                  signals, sigma=sigma, options=options)
        except FitError:
            return None

    def probe(start):
        f = refit(start, replace(opts, max_nfev=PROBE_NFEV, continuations=0))
        return None if f is None else (f.stats.chisqr, f.values())

    point = {k: fit.estimates[k].value for k in free}
    thr = valley_threshold(fit)
    best = restart_from_dips(lambda sets: _cost(logs, base_vals, sets, signals, sigma), point,
                             refit, lambda f: f.stats.chisqr, probe=probe,
                             bar=fit.stats.chisqr - thr)
    if best is None or not fit.stats.chisqr - best.stats.chisqr > thr:
        return fit
    return best


#: the words beside a dead zone these logs only bound
DZ_CAVEAT = ("not identifiable from these logs, masked by the Coulomb friction: record fast "
             "reversals or steps down through zero")
#: the words beside a dead zone the drive only passes through, above the Coulomb friction
DZ_PASSED_CAVEAT = ("not identifiable from these logs: the drive passes through it too fast for "
                    "any sample to show it; record slow ramps through zero or small steps from "
                    "rest")


def _masked_dead_zone(est: dict, upper: float, bc: float, warns: list) -> None:
    """A dead zone the logs only bound, [0, ``upper``] [N m], written as that interval with the
    reason: below the Coulomb friction ``bc`` [N m] it is masked (the rotor moves only while the
    torque exceeds bc); above it, the drive's torque only passes through it (a two-level PRBS:
    no sample dwells there)."""
    below = upper <= 1.1 * bc  # the profile resolves the bound to a few per cent
    est["dz"] = bounded("dz", 0.0, upper, "N m", DZ_CAVEAT if below else DZ_PASSED_CAVEAT)
    why = (f"it is masked by the Coulomb friction bc = {bc:.3g} N m: the rotor only moves while "
           "the torque exceeds bc" if below else "the drive's torque passes through that range "
           "without dwelling in it for a sample")
    warns.append(f"dz is not identifiable from these logs: any dead zone from 0 to {upper:.3g} "
                 f"N m fits equally ({why}); written as that interval, not as a value with a "
                 "standard error (a dz other data determined inside it is kept). Slow inputs "
                 "through zero, fast reversals or steps down reveal it")


#: the words beside a dead zone that falls between two levels of a quantised input
DZ_LEVELS_CAVEAT = ("the input is held at the levels it logged (an integer PWM duty: "
                    "discrete levels): every dead zone between the two around it acts the same "
                    "on these logs")


#: dead zones tried across a masked interval for the value simulations use (:func:`_masked_value`)
MASKED_N = 9


def _masked_value(logs, base_vals, fit, signals, sigma, est, warns) -> None:
    """The value inside a masked dead zone's interval that simulations use (``est["dz"]``,
    written by :func:`_masked_dead_zone`): the interval's middle, unless another of
    :data:`MASKED_N` dead zones across it fits the other estimates as written clearly better
    (by more than two standard errors' rise, :func:`.share_valley.valley_threshold`).

    The interval is read where the profile walked (the fit's point, or its share's valley's
    ends, :func:`_unmask`), while a lumped model's J, tau_e and share may then be moved along
    their valley (:func:`_share_valley`), where the dead zone acts differently: on the paper's
    motor's 500 Hz step logs per volt (bench/pervolt_coverage.py paper-steps-500 seed 5) the
    fit stopped at share 1 with dz 0, the interval [0, 0.65] V read at share 0.05, the share
    moved to 0.48, and the model written with dz at 0.33 V simulated the logs 32 chi-square
    units worse than the same model with dz 0 (the threshold 11). ``est`` updated in place, a
    note when the value moved."""
    e = est["dz"]
    if e.interval is None:
        return
    point = {k: x.value for k, x in est.items() if k in fit.estimates or k == "dz"}
    dzs = np.linspace(e.interval[0], e.interval[1], MASKED_N)
    c = np.nan_to_num(_cost(logs, base_vals, [{**point, "dz": float(d)} for d in dzs], signals,
                            sigma), nan=np.inf)
    k, mid = int(np.argmin(c)), MASKED_N // 2
    if not c[mid] - c[k] > valley_threshold(fit):
        return
    est["dz"] = bounded("dz", *e.interval, e.unit, e.caveat, float(dzs[k]))
    warns.append(Note(f"dz is written as its interval; simulations use dz = {dzs[k]:.3g}, the "
                      "value inside it that fits the other estimates as written best (chi-square "
                      f"{c[mid] - c[k]:.3g} below the interval's middle, {dzs[mid]:.3g})",
                      about=("dz",), severity="note"))


def _masked_reach(est, alike: list[dict[str, float]], warns) -> None:
    """Each estimate's standard error widened to half its farthest reach over ``alike``: the
    points, refitted at dead zones across a masked interval (:func:`_unmask`), that fit as
    well as the fit (only where that is wider). A dead zone the logs only bound moves what
    trades with it: on voltage and speed alone, J, tau_e and the back-EMF share (the dead zone
    acts on the lagged torque) and bc. Measured on the paper's motor's step logs per volt
    (bench/pervolt_coverage.py, the four paper-* cases, 20 seeds each): where the dead zone
    was masked, J' was within 2 standard errors in 17 of 43 runs (27 of 37 where it was not);
    paper-steps-500 seed 5, J' +5.3 % at 3.0 se, with the truth's point (share 0.033, dz
    0.3 V) 4 chi-square units above the fit's floor (the threshold 11), its J off the share's
    valley line drawn at dz = 0. ``est`` updated in place, a note naming what widened."""
    wide = []
    for k, e in list(est.items()):
        vals = [p[k] for p in alike if k in p and k != "dz"]
        if not vals or e.interval is not None or not math.isfinite(e.stderr):
            continue
        se = math.hypot(e.stderr, 0.5 * max(abs(v - e.value) for v in vals))
        if se > 1.01 * e.stderr:
            est[k] = Estimate(k, e.value, se, e.unit, caveat=e.caveat)
            wide.append(f"{k} x{se / e.stderr:.2g}")
    if wide:
        warns.append(Note("standard errors widened to half their reach over the refitted points "
                          "across dz's interval (the other parameters refitted at each dead zone "
                          "from 0 to its upper end fit as well, and move with it): "
                          + ", ".join(wide), about=tuple(w.split()[0] for w in wide),
                          severity="note"))


def input_levels_around(logs, dz: float) -> tuple[float, float] | None:
    """(largest |input| below ``dz``, smallest at or above it) over the logs' samples [input
    unit]; None when every sample is on one side."""
    a = np.unique(np.abs(np.concatenate([np.asarray(lg.u, float) for lg in logs])))
    below, above = a[a < dz], a[a >= dz]
    if not len(below) or not len(above):
        return None
    return float(below[-1]), float(above[0])


def dz_between_levels(logs, vals: dict, e: Estimate) -> Estimate:
    """A hard dead zone acting on the logged input itself (a torque-driven kernel: a torque log,
    or a lumped model with neither an electrical lag nor a back-EMF share, whose dead zone is
    on the applied volts; the input held between samples) is only bounded by the input's
    levels: any dz in (lo, hi], the adjacent |input| levels around it, gives the same
    simulation, so the cost is flat there and its curvature says nothing. When that width
    exceeds 2 standard errors (a quantised input: an integer PWM duty), dz is written as that
    interval; else ``e`` unchanged. Not with an instant current (a share, no lag: the dead
    zone on v - ke w; bench/pervolt_coverage.py ``lr-encoder`` wrote a dz 3 % off as an
    interval between two triangle samples' levels)."""
    torque = all(lg.drive == "tau" for lg in logs)
    on_input = (torque and kernel_values(vals, torque)[1]
                and not float(vals.get("latency", 0) or 0) and vals.get("ramp") is None)
    around = input_levels_around(logs, e.value) if on_input else None
    if around is None or not (around[1] - around[0] > 2 * e.stderr or math.isnan(e.stderr)):
        return e
    return bounded(e.name, around[0], around[1], e.unit, DZ_LEVELS_CAVEAT, value=e.value)


#: the words beside the lumped model's tau_e standard error
TAU_E_CAVEAT = ("a lower bound: its 2-sigma interval held the true L/R in 18 of 20 synthetic "
                "seeds with steps, 14 of 20 on a triangle alone")

#: the secant check moves each parameter by this many of its standard errors (at 2 the rise
#: is dominated by the cost's small bumps, which make it steeper, not flatter)
SECANT_SE = 4.0
#: the most a standard error is widened by the secant check
SECANT_MAX = 10.0


#: a side of the secant check whose line leaves the physical region before this fraction of
#: its +-4 standard errors is not read (its rise would be the cost's small bumps)
SECANT_MIN_REACH = 0.5


def _reach(center: dict[str, float], point: dict[str, float], bounds: dict) -> float:
    """The largest fraction t in [0, 1] of the way from ``center`` to ``point`` that stays
    within ``bounds`` and the physical region (:func:`_limits`): 0 where ``center`` itself
    lies on a bound the line leaves through."""
    t = 1.0
    for k, v in point.items():
        lo, hi = _limits(k, bounds)
        c, d = center[k], v - center[k]
        if d > 0 and c + d > hi:
            t = min(t, max(hi - c, 0.0) / d)
        elif d < 0 and c + d < lo:
            t = min(t, max(c - lo, 0.0) / -d)
    return t


def secant_errors(logs, base_vals, fit, signals, sigma, warns,
                  bounds: dict | None = None) -> dict[str, Estimate]:
    """Standard errors no narrower than the cost's own rise says: a lumped model with an
    electrical lag (tau_e, ke_share free; else nothing changes).

    The covariance comes from the Jacobian at the solution (central differences over 1 %),
    i.e. the cost's local curvature. Where the cost is rough on a finer scale than the
    uncertainty (the dead zone's events move with tau_e, ke_share and dz by whole internal
    steps), that curvature claims more than the cost's rise over the interval it prints:
    measured on bench/lumped_coverage.py's seed 4, the truth sat 46 chi-square units away by
    the covariance and 8 by the cost. Here each parameter is moved by +-4 standard errors along
    the covariance's own line (the others following their regression on it: the profile's
    direction), the cost evaluated, and where it rises by less than the covariance predicts
    (16 x the reduced chi-square x the correlated-residual inflation squared), the standard
    errors are widened by the square root of the ratio, with a note. Never narrowed.

    A line that leaves the physical region (``bounds``, a share above 1, a negative dead zone)
    stops at its edge, a fraction t of the way, and its rise is read against t^2 of the
    expected one; a side that reaches less than :data:`SECANT_MIN_REACH` is not read (a model
    the fit cannot take says nothing about its interval: measured over bench/pervolt_coverage.py,
    44 of 94 checks had such a line, and 30 of 466 widenings were set by one, by 1.2-1.5x)."""
    free = list(fit.estimates)
    lines = _profile_lines(fit, (SECANT_SE, -SECANT_SE))
    if not lines:
        return {}
    center = {k: fit.estimates[k].value for k in free}
    reach = [_reach(center, pt, bounds or {}) for pt in lines]
    read = [s for s, t in enumerate(reach) if t >= SECANT_MIN_REACH]
    sets = [center, *({k: center[k] + reach[s] * (lines[s][k] - center[k]) for k in free}
                      for s in read)]
    cost = dict(zip([None, *read], _cost(logs, base_vals, sets, signals, sigma), strict=True))
    infl = fit.covariance.inflation if fit.covariance and fit.covariance.inflation > 1 else 1.0
    expect = SECANT_SE ** 2 * max(fit.stats.redchi, 1.0) * infl ** 2
    out, wide = {}, []
    for j, k in enumerate(free):
        # the flatter side, per the square of the way it reached
        sides = [(cost[s] - cost[None]) / reach[s] ** 2 for s in (2 * j, 2 * j + 1) if s in cost]
        if not sides:
            continue
        rise = min(sides)
        # a cost lower out there (the local stage stopped short of the valley's floor): the
        # widest factor, SECANT_MAX
        # (a rise within 1 % of the expected one is the bowl: no "x1" widening)
        factor = (min(math.sqrt(expect / max(rise, 1e-300)), SECANT_MAX)
                  if rise < 0.99 * expect else 1.0)
        if factor > 1.0:
            e = fit.estimates[k]
            out[k] = Estimate(k, e.value, e.stderr * factor, e.unit)
            wide.append(f"{k} x{factor:.3g}")
    e = out.get("tau_e", fit.estimates["tau_e"])
    out["tau_e"] = Estimate("tau_e", e.value, e.stderr, e.unit, e.vary, caveat=TAU_E_CAVEAT)
    warns.append("tau_e's standard error is a lower bound: on synthetic voltage + speed logs "
                 "(bench/lumped_coverage.py, bench/pervolt_coverage.py) its 2-sigma interval "
                 "held the true L/R in 18 of 20 seeds with steps, 14 of 20 on a triangle alone")
    if wide:
        warns.append("standard errors widened where the cost rises less over +-4 standard "
                     "errors than the local curvature says (the dead zone's events make it "
                     "rough on a finer scale): " + ", ".join(wide))
    return out


def _share_valley(logs, base_vals, fit, signals, sigma, est, warns) -> None:
    """A lumped model's back-EMF share, J and tau_e read along their valley of equal linear
    response (:mod:`.share_valley`): ``est`` updated in place, a note when they moved."""
    if "ke_share" not in est or "tau_e" not in est:  # no lag: the share trades with no J
        return
    moved, why = share_interval(lambda sets: _cost(logs, base_vals, sets, signals, sigma),
                                fit, est)
    est.update(moved)
    if why:
        warns.append(Note(why, about=("J", "tau_e", "ke_share"), severity="note"))


def _seen_dead_zone(logs, base_vals, held, fit, signals, sigma, est, warns, refit) -> None:
    """A dead zone the logs see: its interval along the profile line
    (:func:`_profile_dead_zone`), then, on a quantised input, the levels around it
    (:func:`dz_between_levels`); ``est`` updated in place."""
    _profile_dead_zone(logs, base_vals, fit, signals, sigma, est, warns, refit)
    if "dz" in est:
        est["dz"] = dz_between_levels(logs, {**base_vals[0], **held}, est["dz"])


def _profile_dead_zone(logs, base_vals, fit, signals, sigma, est, warns, refit) -> None:
    """dz from its profile-likelihood interval (:mod:`.dead_zone`: the cost is a staircase in
    dz): ``est`` updated in place, every free parameter moved to the interval's middle with
    its standard error kept (a wider one from :func:`secant_errors` too), dz's the profile's;
    a note when that changed anything visibly. With a lumped model's electrical lag free
    (tau_e, ke_share) the dead zone's events move with them by internal steps too and the
    line (a regression on dz) is no profile there (moved along it, tau_e's 2-sigma interval
    held the truth in 14 of bench/lumped_coverage.py's 20 seeds, 16 before): the profile is
    refitted at each dead zone instead (:func:`.dead_zone.refit_interval`, ``refit``:
    :func:`_refit_at`), J, tau_e and the share left where their valley put them
    (:func:`_share_valley`) when it moved them."""
    if "tau_e" in fit.estimates:
        moved, why = refit_interval(refit, fit)
        valley = {k for k in ("J", "tau_e", "ke_share")
                  if k in est and est[k].value != fit.estimates[k].value}
        moved = {k: e for k, e in moved.items() if k not in valley}
    else:
        moved, why = dead_zone_interval(
            lambda sets: _cost(logs, base_vals, sets, signals, sigma), fit)
    for k, e in moved.items():
        se = max(e.stderr, est[k].stderr) if k == "dz" else est[k].stderr
        est[k] = Estimate(k, e.value, se, e.unit, caveat=est[k].caveat)
    if why:
        warns.append(Note(why, about="dz", severity="note"))


def fit_nonlinear(logs, model: Model, free=None, signals=None, dead_zone: bool = False,
                  grid: bool = True, max_nfev: int = 200,
                  priors: bool = True, noise_model: int = 0,
                  local_only: bool = False) -> NonlinearResult:
    """Fit J, bv, bc, dz (voltage logs) or J, bv, bc, tau0 (torque logs) by simulation error.

    ``free``: parameters to fit (subset of J, bv, bc, dz, tau0); ``signals``: measured signals
    in the cost (default: the measured speed and angle present); ``dead_zone``: also fit dz on
    torque-driven logs. R, L, km (voltage logs) and the model's other parameters are held.
    ``priors``: combine with the estimates earlier stages wrote (:func:`stage_priors`); False
    lets these logs alone decide. ``noise_model``: the local stage's AR noise model order (0:
    white; closed-loop logs, :func:`pmdcid.fit.simfit.fit_simulation`). ``local_only``: the
    local stage alone, none of the checks after it (the dead zone's, the inertia's and the
    share's restarts, the secant check): a start compared with others by its chi-square
    (:func:`pmdcid.identify.runners.stage_nonlinear`'s lag), never a result to write.
    The model is not modified: call :meth:`NonlinearResult.apply`.
    """
    run = partial(_best_start, logs, model, free, signals, dead_zone, grid, max_nfev, priors,
                  noise_model, local_only=local_only)
    with blas_single_thread():
        res = run()
        if free is None and not offset_shown(res.estimates.get("tau0"), res.stats.ndata):
            e = res.estimates["tau0"]
            again = run(offset=False)
            again.warnings.insert(0, Note(offset_note(e.value, e.stderr, e.unit, res.stats.ndata)
                                          + held_offset(model), about="tau0",
                                          severity="note"))
            res = again
        return res


def offset_shown(e: Estimate | None, ndata: int) -> bool:
    """True when there is no fitted tau0 to judge, or it passes the rule an added effect meets
    (:func:`.offset.offset_evident`; an undetermined one, its standard error not
    finite, does not)."""
    if e is None or not e.vary:
        return True
    return offset_evident(e.value, e.stderr, ndata)


def _local_bounds(logs, free, start: dict, guessed) -> dict[str, tuple[float, float]]:
    """The local stage's bounds: J and bv within :data:`REFINE_RANGE` of their start (cubed
    for a guessed one), a lumped model's lag above its floor (it stays a lag: tau_e = 0 is the
    model without it)."""
    bounds = {k: (start[k] / REFINE_RANGE ** (3 if k in guessed else 1),
                  start[k] * REFINE_RANGE)
              for k in ("J", "bv") if k in free and start[k] > 0}
    if "tau_e" in free:
        bounds["tau_e"] = (TAU_E_FLOOR * min(lg.dt for lg in logs), 1.0)
    return bounds


def _best_start(*args, offset: bool = True, local_only: bool = False) -> NonlinearResult:
    """The fit from each start the logs give (:func:`.nonlinear_setup.competing_starts`:
    torque-driven logs), the lowest chi-square kept; a start that fails to fit is passed over."""
    best = _fit_nonlinear(*args, offset=offset, local_only=local_only)
    for pick in range(1, best.starts):
        try:
            other = _fit_nonlinear(*args, offset=offset, pick=pick, local_only=local_only)
        except FitError:
            continue
        if other.stats.chisqr < best.stats.chisqr:
            best = other
    return best


def _fit_nonlinear(logs, model, free, signals, dead_zone, grid, max_nfev,
                   priors=True, noise_model=0, offset=True, pick=0,
                   local_only=False) -> NonlinearResult:
    t_start = time.perf_counter()
    check_logs(logs)
    prior = stage_priors(model, KNOWN_FREE, STAGE) if priors else {}
    signals, warns = chosen_signals(logs, signals)
    free = free_parameters(logs, model, free, dead_zone, warns, offset)
    work, start, guessed, nstarts = working_model(logs, model, free, warns, pick)
    base_vals = [param_values(work, lg.drive == "tau", {k: start[k] for k in free})
                 for lg in logs]
    sigma = noise_levels(logs, signals)
    if not any(sigma):
        raise FitError(f"no log carries {' or '.join(signals)} to fit")
    require_motion(logs, sigma)
    tscale = _torque_scale(logs, base_vals)
    best, nsets = ({k: start[k] for k in free}, 0)
    if grid:
        best, nsets = _grid_search(logs, base_vals, start, free, signals, sigma, tscale)
    ndata = sum(lg.n * len(sg) for lg, sg in zip(logs, sigma, strict=True))
    masked = False
    ls_free = list(free)
    if "dz" in free and len(free) > 1:
        # a dead zone below the static friction never acts on a slowly driven rotor (it moves
        # only while |km i| > bc > dz): the cost is then flat in dz from 0 up to about bc
        dzs, c, thr, _ = dz_profile(logs, base_vals, best, signals, sigma, ndata, 13)
        masked = bool(c[0] - c.min() <= thr)
        if masked:
            ls_free.remove("dz")
            best["dz"] = 0.0
            work.set("dz", 0.0, stage="start")
            # and in the values every later cost is read with (the secant check, the restarts,
            # the share's valley): left at its start, they read a model the fit never had
            base_vals = [{**b, "dz": 0.0} for b in base_vals]
    for k in ("bc", "dz", "tau0"):
        # the local stage scales each parameter by its start: a start at exactly 0 would make
        # its finite-difference step as large as 1 N m, and one within rounding of 0 (an
        # earlier fit's value at its bound, 1e-17) a step of 1e-19, from which it never moves
        # (bench/pervolt_coverage.py lr-chirp seed 7: the lag's fit kept bc at 3e-20 from the
        # fit without a lag, chi-square 7103 against the truth's 4089)
        if k in ls_free and abs(best[k]) <= ZERO_START * tscale:
            best[k] = 1e-3 * tscale
    bounds = _local_bounds(logs, free, start, guessed)
    # how a slow log's input varied between samples, when it matters (.ramp_profile)
    prof = hold_profile(logs, start, free, partial(
        _chisqr_and_J, logs, work, ls_free, signals, best, sigma, max_nfev, bounds, prior))
    held = {"ramp": prof.value} if prof else {}
    base_vals = [{**b, **held} for b in base_vals]
    opts = FitOptions(max_nfev, noise_model=noise_model)
    fit = fit_simulation(logs, work, _parameters(ls_free, best, bounds, DIFF_STEP,
                                                 prior_terms(prior), held),
                         signals, sigma=sigma, options=opts)
    filters = fit.noise_filters  # what the noise model did, said by the route line
    # the same criterion as the fit they may replace (its noise model included)
    fit = _polish(logs, work, ls_free, signals, fit, sigma, opts, bounds,
                  prior_terms(prior), held, wide=True)
    if local_only:
        return NonlinearResult(dict(fit.estimates), fit, signals, [lg.path for lg in logs], start,
                               best, nsets, time.perf_counter() - t_start, warns,
                               {n: prior[n][0] for n in fit.priors}, starts=nstarts)
    for _ in range(SCAN_ROUNDS):  # each restart may stop on the next step of a rough cost
        scanned = _scan_inertia(logs, work, ls_free, signals, fit, sigma, opts, bounds,
                                prior_terms(prior), held, base_vals)
        if scanned is fit:
            break
        fit = scanned
    fit = _valley_restart(logs, work, ls_free, signals, fit, sigma, opts, bounds,
                          prior_terms(prior), held, base_vals)
    fit.noise_filters = fit.noise_filters or filters
    fits = (partial(_refit_at, logs, work, free, signals, sigma, opts, bounds,
                    prior_terms(prior), held),
            lambda st: fit_simulation(logs, work, _parameters(free, st, bounds, DIFF_STEP,
                                                              prior_terms(prior), held),
                                      signals, sigma=sigma, options=opts))
    if "dz" in free and len(free) > 1:
        fit, upper, point, alike = _check_dead_zone(logs, base_vals, best, fit, signals, sigma,
                                                    ndata, fits)
        masked = upper is not None
    est = dict(fit.estimates)
    est.update(secant_errors(logs, base_vals, fit, signals, sigma, warns, bounds))
    _share_valley(logs, base_vals, fit, signals, sigma, est, warns)
    if not masked:
        _seen_dead_zone(logs, base_vals, held, fit, signals, sigma, est, warns, fits[0])
    if masked:
        _masked_dead_zone(est, upper, est["bc"].value if "bc" in est else point.get("bc", 0.0),
                          warns)
        _masked_value(logs, base_vals, fit, signals, sigma, est, warns)
        _masked_reach(est, alike, warns)
    if prof:
        est.update(prof.estimates(est.get("J")))
    warns.extend(fit_warnings(fit, est, tscale, masked))
    hold = hold_warning(logs, est["J"].value if "J" in est else math.nan,
                        est["bv"].value if "bv" in est else math.nan, est.get("ramp"))
    if hold:
        warns.append(hold)
    used = {n: prior[n][0] for n in fit.priors}
    return NonlinearResult(est, fit, signals, [lg.path for lg in logs], start, best, nsets,
                           time.perf_counter() - t_start, warns, used, starts=nstarts)

