"""diagnose's last steps on all the data: prune what the final model does not support, polish.

*Prune*: the added effects are refitted together on all the data; an effect whose removal costs
no decisive ΔBIC (backward elimination), or whose size in the final model is under ``min_z``
standard errors (allowing for a correlated residual), is removed and the rest refitted, until
every kept effect passes its rules in the model that is written.

*Polish*: the dead zone when the data cannot see it, profile and correlated-residual standard
errors of the switching parameters.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from pmdcid.diagnose.candidates import effect_free, effect_z, unphysical
from pmdcid.diagnose.lagdz import lag_refits, masked_on_profile, refitted_line, widen
from pmdcid.diagnose.lagvalley import share_correlations, valley_errors, valley_restart
from pmdcid.diagnose.starts import profile_stderr
from pmdcid.fit.problem import FitOutcome, Problem
from pmdcid.fit.results import Estimate, bounded
from pmdcid.identify.dead_zone import dead_zone_interval
from pmdcid.identify.instant import lag_bound_of
from pmdcid.identify.nonlinear import DZ_CAVEAT, crossing_upper
from pmdcid.model import EFFECTS
from pmdcid.model.effects import effect_param_specs
from pmdcid.model.lumped import LUMPED_ONLY, is_lumped, lumped_unit
from pmdcid.runtime.cpus import pmap

#: added effects that can lower the total friction (removed, the last added first, when the
#: final model's friction is negative somewhere within the logged speeds)
LOWERING = ("quadratic_drag", "viscous_asymmetry", "friction_curve")


def dead_zone_range(problem: Problem, fo: FitOutcome, n: int = 13,
                    rel: float = 1e-3) -> float | None:
    """Upper end [N m] of the dead zones that fit as well as the fit ``fo`` does, or None.

    A dead zone below the breakaway torque never acts on a rotor that turns only while the
    torque exceeds it: every dz from 0 up to some level fits equally (within two standard errors,
    4 x the reduced chi-square, or ``rel`` of the chi-square). Returns that level when dz = 0 is
    among them (the dead zone is not identified), None when the data see the dead zone; the
    level is read between the grid's points (:func:`~pmdcid.identify.nonlinear.crossing_upper`,
    as fit-nonlinear reads it): on the grid's last point inside, a band narrower than its first
    step was written "between 0 and 0 N m" (guanlunlu-l298n driven as torque, session 18).
    """
    v = fo.values
    c = fo.chi2["all"]
    thr = max(two_se(problem, fo), rel * c)
    top = 1.5 * max(v.get("bc", 0.0) + max(v.get("fs", 0.0), 0.0), v.get("dz", 0.0), 1e-300)
    dzs = np.linspace(0.0, top, n)
    cost = np.array([problem.chi2({**v, "dz": d})["all"] for d in dzs])
    if cost[0] - c > thr:
        return None
    return crossing_upper(dzs, cost, thr)


def two_se(problem: Problem, fo: FitOutcome, part: str = "all") -> float:
    """A chi-square rise (on ``part``: all data, or the fitted part) of two standard errors at
    the fit ``fo``: 4 x its reduced chi-square (at least 4)."""
    c = fo.chi2[part]
    return 4.0 * max(c / max(problem.count(part) - len(fo.estimates), 1), 1.0)


def _inflation(problem: Problem, fo: FitOutcome, free: list[str]) -> float:
    """How much wider than the white-residual formula the residual's correlation makes the
    standard errors at ``fo`` (the block sandwich's, :meth:`Problem.envelope_errors`; 1 where
    the residual is white or the Jacobian cannot be inverted): the factor a chi-square
    difference's two standard errors widen by, squared."""
    info = problem.envelope_errors(fo.values, free)[1]
    return max(info.inflation, 1.0) if info is not None else 1.0


def _weakest(problem: Problem, fo: FitOutcome, added: list[str], base_free: list[str],
             fit, bic_threshold: float) -> tuple[str, FitOutcome] | None:
    """Backward check of several added effects: each is removed in turn and the rest refitted;
    returns (the effect whose removal costs least, the refit without it) when that cost is not
    decisive (ΔBIC of the removal, all data, below -``bic_threshold``), else None."""
    if len(added) < 2:
        return None
    n = problem.count("all")
    worst = None
    for e in added:
        rest = base_free + [p for a in added if a != e for p in effect_free(a)]
        off = {p.name: p.neutral for p in EFFECTS[e].params}
        without = fit({**fo.values, **off}, rest, "all")
        d = n * math.log(max(without.chi2["all"], 1e-300) / max(fo.chi2["all"], 1e-300))
        d -= len(effect_free(e)) * math.log(max(n, 2))
        if worst is None or d < worst[2]:
            worst = (e, without, d)
    return (worst[0], worst[1]) if worst[2] < -bic_threshold else None




def _unchoose(history, name: str) -> None:
    for c in history:
        if c.effect == name:
            c.chosen = False


def prune(run, final: FitOutcome, added: list[str], notes: list[str],
          history) -> FitOutcome:
    """Backward elimination on all the data (``added`` is updated in place)."""
    weak = _weakest(run.problem, final, added, run.base_free, run.fit, run.settings.rules.bic)
    while weak is not None:
        # an effect that the final fit no longer needs (another one took its part) goes
        added.remove(weak[0])
        final = weak[1]
        notes.append(f"{weak[0]} dropped: with the other added effects it no longer "
                     "improves the fit decisively")
        _unchoose(history, weak[0])
        weak = _weakest(run.problem, final, added, run.base_free, run.fit, run.settings.rules.bic)
    return final


def free_of(run, added: list[str]) -> list[str]:
    """The final refits' free parameters: the base's, the added effects', and a lumped model's
    electrical lag (tau_e, ke_share, :mod:`pmdcid.model.lumped`) where it has one: the share
    sets where the dead zone acts, and the joint fit found it without the effects (held, dz
    took up the difference: bench/pervolt_coverage.py --diagnose, docs/identification.md)."""
    lag = [p for p in LUMPED_ONLY if added and run.vals0.get("tau_e", 0.0) > 0]
    free = run.base_free + [p for e in added for p in effect_free(e)] + lag
    return list(dict.fromkeys(free))  # the lag may be free in the base already (lawlag.py)


def inside(par, upper: float) -> bool:
    """Whether the model's dead zone ``par`` (any stage's, bounded or not) lies in [0,
    ``upper``]."""
    return par is not None and math.isfinite(par.value) and 0.0 <= par.value <= upper


def settle_dead_zone(run, final: FitOutcome, free: list[str],
                     notes: list[str]) -> tuple[FitOutcome, list[str]]:
    """The dead zone when these logs cannot see it: the interval's midpoint (not identified) or
    the model's own value (fits as well); returns the fit and the parameters still free."""
    problem = run.problem
    if "dz" not in free:
        return final, free
    upper, spread = (masked_on_profile(run, final, free) if lag_refits(run, free)
                     else (None, {}))
    sub = sub_sample_masked(run, final, free) if upper is None else None
    if sub is not None:
        upper = sub
        notes.append(f"dz kept as the earlier fit's interval, 0 to {sub:.3g} (the model's value "
                     "inside where it lies there): the armature's lag diagnose took "
                     f"({1e3 * final.values['tau_e']:.3g} ms) is under a sample, so a dead zone "
                     "shows on these logs only as a start from rest delayed by less than a "
                     "sample, which a sensor delay, gear backlash or the loop's timing make "
                     "alike")
    # with the lag diagnose took, the model's dz was settled without it: masked on the
    # refitted profile (lagdz.py), the interval is read there; else as without the lag (a
    # dz seen there and refitted from the profile's lowest point, or moved to the interval's
    # middle, went to 3.4-5.1 V on the L298N rig, whose commands never fall below 6 V: a dead
    # zone up to there only delays the onset; the model's 1.8 V fits as well)
    if upper is None:
        upper = dead_zone_range(problem, final)
    if upper is not None:
        # its refit value and standard error would mean nothing: written as the interval, as
        # fit-nonlinear does, the others refitted at the point inside that the model keeps: the
        # model's own dz where it lies inside (other data determined it, or an earlier stage
        # bounded it: these logs cannot see it, so they leave it where it was; a refit drifts
        # along the flat cost, and its interval's midpoint can be a dead zone no earlier fit
        # had), else the midpoint
        free = [p for p in free if p != "dz"]
        kept = inside(run.model.parameters.get("dz"), upper)
        point = run.vals0["dz"] if kept else 0.5 * upper
        final = run.fit({**final.values, "dz": point}, free, "all")
        unit = lumped_unit("N m") if is_lumped(run.model) else "N m"
        final.estimates["dz"] = bounded("dz", 0.0, upper, unit, DZ_CAVEAT, point)
        widen(final.estimates, spread)  # the others move with dz across it (lagdz.py)
        if sub is None:  # else said above
            notes.append(f"dz is not identifiable with the added effects: any dead zone from 0 "
                         f"to {upper:.3g} {unit} fits equally (below the breakaway torque); "
                         + ("the model's dz lies inside and is kept" if kept else
                            "written as that interval, not as a value with a standard error"))
    else:
        final, free = _model_dead_zone(run, final, free, notes)
    return final, free


def sub_sample_masked(run, final: FitOutcome, free: list[str]) -> float | None:
    """The upper end [N m] of the dead zone's interval in the model (an earlier fit found it
    masked: the logs' samples do not show it) where diagnose took the armature's lag and that
    lag is under the logs' sample period; else None. With such a lag a dead zone delays a start
    from rest by tau_e ln(V/(V - dz)), a fraction of a sample, and the refit reads it from that
    alone: bench/newrigs.py lego seed 6 (an 11 ms loop-timed grid, L/R 0.7 ms, 2 degrees of
    backlash) moved the masked dz (0 to 1.03 V, the model's 0.51) to 1.81 +- 0.44 V with a lag
    of 2.5 ms, and the held-out sines' error rose 0.019 -> 0.047. Such a shift has other causes
    the model lacks (a delay under a sample, backlash, the loop's timing), as a sensor delay
    under :data:`~pmdcid.identify.latency.MIN_SAMPLES` samples is not taken on its own
    either. Only where diagnose added no effect (none free): the earlier interval was read on
    the model without it, and an effect can show a dead zone that model hid (bench/thinlogs.py
    b2:viscous_asymmetry seed 11: bc 0 and dz masked at 0 without the asymmetry, 0.19 and
    0.068 +- 0.004 V with it)."""
    par = run.model.parameters.get("dz")
    if (not lag_refits(run, free) or par is None or par.interval is None
            or effect_param_specs().keys() & set(free)):
        return None
    dt = min(log.dt for log in run.problem.logs)
    return float(par.interval[1]) if final.values.get("tau_e", 0.0) < dt else None


def _model_dead_zone(run, final: FitOutcome, free: list[str],
                     notes: list[str]) -> tuple[FitOutcome, list[str]]:
    """The model's own dz (from fit-nonlinear's slow reversals) where it fits these logs as
    well as the refitted one: the others refitted with dz held there (its profile, not the
    refit's values with dz swapped in: where the others trade with dz, a swap alone rises by
    more than the profile does), kept when the chi-square (all data) rises by at most two
    standard errors (4 x the reduced chi-square, x the square of :func:`_inflation` where the
    residual is correlated). The dead zone shows only at a few switching
    instants: these logs then do not move it. A lag diagnose took that the steps had not
    resolved made a masked dead zone look seen at 1.41 +- 0.67 V on bench/newrigs.py's LEGO-like
    rig (the model's 0.40 V 1.5 of those errors away), and every held-out sine rose."""
    others = [p for p in free if p != "dz"]
    held = run.fit({**final.values, "dz": run.vals0["dz"]}, others, "all")
    c = final.chi2["all"]
    if held.chi2["all"] - c > two_se(run.problem, final) * _inflation(run.problem, final,
                                                                        free) ** 2:
        return final, free
    notes.append("dz kept from the model: it fits these logs as well as a refitted one")
    return held, others


def honest_errors(run, final: FitOutcome, free: list[str], notes: list[str]) -> None:
    """Standard errors the data support: the profile's for the switching parameters (the
    Jacobian sees nothing between events) and the correlated-residual (HAC) ones, whichever is
    larger (``final.estimates`` updated in place); a free lag's J, tau_e and share widened
    along their valley (:func:`~pmdcid.diagnose.lagvalley.valley_errors`); then dz's
    profile-likelihood interval (:func:`dead_zone_line`)."""
    problem = run.problem
    for name in ("bc", "dz"):
        est = final.estimates.get(name)
        if est is not None and name in free:
            se = profile_stderr(problem, final.values, name, final.stats.redchi)
            if math.isfinite(se) and not se <= est.stderr:
                final.estimates[name] = Estimate(name, est.value, se, est.unit)
    # the refits' errors assume white residuals; on real data the residual is correlated
    hac, info, curv = problem.envelope_errors(final.values, list(final.estimates))
    for name, se in hac.items():
        est = final.estimates[name]
        if math.isfinite(se) and se > est.stderr and name in free:
            final.estimates[name] = Estimate(name, est.value, se, est.unit)
    if info is not None and (info.inflation > 1.5 or info.lower_bound):
        notes.append(info.describe())
    names = [n for n in final.estimates if n in final.values]  # curv's order
    valley_errors(run, final, free, info, notes, share_correlations(names, curv))
    lag_left_open(run, final, free, notes)
    if "dz" in free and curv is not None:
        if lag_refits(run, free):
            refitted_line(run, final, free, line_fit(final, names, curv), notes)
        else:
            dead_zone_line(problem, final, names, curv, notes)


def lag_left_open(run, final: FitOutcome, free: list[str], notes: list[str]) -> None:
    """An instant-current model (the steps left its lag open: identify/instant.py) that the
    final refit kept without a lag: each free parameter's standard error at least the model's,
    which reach a fit with the lag at the steps' bound (``final.estimates`` updated in place;
    a refit with tau_e held at 0 says only how well it fits at 0)."""
    bound = lag_bound_of(run.model)
    if not math.isfinite(bound) or final.values.get("tau_e", 0.0) > 0:
        return
    kept = []
    for name in free:
        est, par = final.estimates.get(name), run.model.parameters.get(name)
        if est is None or par is None or not math.isfinite(par.stderr):
            continue
        if not est.stderr >= par.stderr:
            final.estimates[name] = Estimate(name, est.value, par.stderr, est.unit,
                                             caveat=est.caveat)
            kept.append(name)
    if kept:
        notes.append(f"{', '.join(kept)}: standard errors kept at the model's, which reach a "
                     f"fit with the lag the steps left open at its bound ({1e3 * bound:.3g} ms)")


def line_fit(final: FitOutcome, names: list[str], curv: np.ndarray) -> SimpleNamespace:
    """The fit as the profile line reads it (:func:`pmdcid.identify.dead_zone.profile_line`):
    the estimates ``names``, their envelope ``(J'J)^-1`` ``curv``, no held part, no priors."""
    return SimpleNamespace(estimates={n: final.estimates[n] for n in names}, curvature=curv,
                           held_cov=None, priors={}, prior_weight=1.0)


def dead_zone_line(problem: Problem, final: FitOutcome, names: list[str], curv: np.ndarray,
                   notes: list[str]) -> None:
    """dz's standard error after the effects were added, from its profile-likelihood interval
    as fit-nonlinear reads it (:func:`pmdcid.identify.dead_zone.dead_zone_interval`: the cost
    is a staircase in dz; the free parameters ``names`` following on the profile line, ``curv``
    their envelope ``(J'J)^-1``): a quarter of the interval's width where that is wider,
    never narrower (``final`` updated in place, a note when it widened). The values stay the
    refit's: moved to the interval's middle with an added effect, the total friction could
    turn negative within the logged speeds (tests/system/test_diagnose.py's quadratic drag)."""
    shim = line_fit(final, names, curv)

    def cost(sets):
        return pmap(lambda s: problem.chi2({**final.values, **s})["all"], sets)

    moved, _ = dead_zone_interval(cost, shim)
    est = final.estimates["dz"]
    if "dz" not in moved or not moved["dz"].stderr > est.stderr:
        return
    final.estimates["dz"] = Estimate("dz", est.value, moved["dz"].stderr, est.unit)
    mid = moved["dz"].value
    notes.append(f"dz's standard error {est.stderr:.2g} -> {moved['dz'].stderr:.2g}: a quarter "
                 "of its profile-likelihood interval's width (the cost is a staircase in dz, "
                 f"flat between the dead zone's events; the interval's middle {mid:.5g})")


def finalise(run, cur: FitOutcome, added: list[str], notes: list[str], history):
    """Refit the added effects on all data (a free lag's fit restarted from its valley's other
    dips, :func:`~pmdcid.diagnose.lagvalley.valley_restart`), prune, polish, and remove (then
    refit without) any effect under ``min_z`` standard errors in the polished model, until all
    pass. Returns the final fit and its free parameters (``added`` updated in place)."""
    final = run.robust_fit(cur.values, free_of(run, added), "all")
    final = valley_restart(run, final, free_of(run, added), notes)  # a free lag's other dips
    while True:
        final = prune(run, final, added, notes, history)
        final, free = settle_dead_zone(run, final, free_of(run, added), notes)
        info: list[str] = []
        honest_errors(run, final, free, info)
        sizes = {e: effect_z(EFFECTS[e], final) for e in added}
        weak = [e for e in added if not sizes[e] >= run.settings.rules.min_z]
        bad = unphysical(final, run.ctx0)
        lowering = [e for e in added if e in LOWERING]
        if not weak and not (bad and lowering):
            notes.extend(info)
            return final, free
        if weak:
            e = min(weak, key=lambda a: sizes[a])
            why = (f"{sizes[e]:.2g} standard errors in the final model (all data, correlated "
                   f"residual allowed for) < {run.settings.rules.min_z:g}")
        else:
            e, why = lowering[-1], f"in the final model, {bad}"
        added.remove(e)
        _unchoose(history, e)
        notes.append(f"{e} removed: {why}")
        off = {p.name: p.neutral for p in EFFECTS[e].params}
        final = run.fit({**final.values, **off}, free_of(run, added), "all")
