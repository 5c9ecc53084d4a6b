"""The lumped lag's back-EMF share along its valley, in diagnose's final model (issue 24).

Per volt, a lumped model with its electrical lag free (``tau_e``, ``ke_share``) answers the
voltage along a valley of equal linear response: the share trades with J and tau_e, only the
friction and the dead zone telling its points apart (:mod:`pmdcid.identify.share_valley`).
fit-nonlinear reads that valley; diagnose's final refits, which free the lag once diagnose
took it (:mod:`.lawlag`, :mod:`.lag`) or the model came with it, did not, and two things went
wrong there (``python bench/lawlag.py --truths none --rates 500 --lags 2,4 --seeds 20``):

- the local refit stops in a dip of the valley far from its floor, the friction and the dead
  zone bent to suit: J' 4-6 of its standard errors off, bc' and bv' 4-6 too, the dead zone
  read as masked. Seed 13 (L/R 2 ms): share 0.54 for 0.997, chi-square 198 above the refit
  from the valley's other dip at share 1. :func:`valley_restart` refits the final model from
  the valley's other dips (:data:`VALLEY_STARTS` of them, lowest first: the local minima of
  the cost along :data:`~pmdcid.identify.share_valley.DIP_SHARES`, the dead zone profiled, but
  the grid share nearest the fit's) and keeps the lowest chi-square where it is lower by more
  than two standard errors' rise (the correlated residual allowed for). Not from
  :data:`~pmdcid.identify.share_valley.GRID_STARTS` as well: diagnose starts from
  fit-nonlinear's model, which restarted from them already;
- where the valley's floor is flat, the local covariance understates how far J, tau_e and the
  share may move along it. :func:`valley_errors` reads the interval of shares that fit as well
  (:func:`~pmdcid.identify.share_valley.share_range`, fit-nonlinear's reading) and widens
  their standard errors to the root mean square distance from the fit's value to a share
  uniform over that interval (the local error with the share held, the interval's spread and
  the value's offset from its middle combined: the local error's own part along the valley is
  the linearisation of a cost flat there, ke_share ± 40 where the valley spans 0 to 1).
  The values stay the fit's, as diagnose's dead-zone readings keep them
  (:func:`~pmdcid.diagnose.final.dead_zone_line`, :mod:`.lagdz`).
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

from pmdcid.fit.problem import FitOutcome
from pmdcid.identify.share_valley import (
    NAMES,
    VALLEY_STARTS,
    at_share,
    dips,
    pm,
    restart_from_dips,
    share_range,
    valley_points,
    valley_threshold,
)
from pmdcid.runtime.cpus import pmap


def valley_free(free: list[str]) -> bool:
    """Whether the refit frees the lag's valley: J, tau_e, the share and bv."""
    return all(k in free for k in (*NAMES, "bv"))


def _cost(run, vals: dict[str, float], part: str = "all"):
    problem = run.problem
    return lambda sets: pmap(lambda s: problem.chi2({**vals, **s})[part], sets)


def valley_restart(run, fo: FitOutcome, free: list[str], notes: list[str] | None = None,
                   part: str = "all") -> FitOutcome:
    """The fit ``fo`` of ``free`` (on ``part``: all data, or the fitted part where diagnose
    takes the lag in a round, :mod:`.lawlag`) refitted from the valley's other dips (module
    docstring): the lowest chi-square kept where it is decisively lower (:func:`_decisive`);
    a note in ``notes`` when a restart won."""
    if not valley_free(free):
        return fo
    point = {k: fo.values[k] for k in free}
    best = restart_from_dips(_cost(run, fo.values, part), point,
                             lambda st: run.fit({**fo.values, **st}, free, part),
                             lambda f: f.chi2[part], fine=False, grid=False)
    if best is None or best.chi2[part] >= fo.chi2[part]:
        return fo
    if not _decisive(run, fo, best, free, part):
        return fo
    if notes is not None:
        notes.append(
            f"the final fit restarted along the back-EMF share's valley (its share trades with "
            f"J and tau_e at equal linear response): ke_share {fo.values['ke_share']:.3g} -> "
            f"{best.values['ke_share']:.3g}, J {fo.values['J']:.5g} -> {best.values['J']:.5g}, "
            f"chi-square {fo.chi2['all']:.6g} -> {best.chi2['all']:.6g}")
    return best


def _decisive(run, fo: FitOutcome, best: FitOutcome, free: list[str],
              part: str = "all") -> bool:
    """Whether ``best`` fits ``part`` better than ``fo`` by more than two standard errors' rise
    (:func:`~pmdcid.identify.share_valley.valley_threshold` at ``fo``, its correlated
    residual allowed for): a dip that fits only as well is no reason to move (LEGO-like rig,
    tests/diagnose/test_lag_resolved.py: 16.8 lower against a threshold of about 90, the dead
    zone at 1.4 V on the lagged voltage, every held-out sine's error doubled)."""
    _, info, _ = run.problem.envelope_errors(fo.values, free)
    shim = SimpleNamespace(covariance=info, stats=fo.stats)
    return fo.chi2[part] - best.chi2[part] > valley_threshold(shim)


def valley_errors(run, final: FitOutcome, free: list[str], info, notes: list[str],
                  rho: dict[str, float] | None = None) -> None:
    """J's, tau_e's and the share's standard errors in ``final`` read on their valley where
    shares across an interval fit as well (module docstring; ``info``: the covariance's,
    whose inflation sets the threshold with the reduced chi-square); a note when they were.
    ``rho``: each one's local correlation with the share, where known: the local error then
    enters with the share held (:func:`~pmdcid.identify.share_valley.at_share`, as
    fit-nonlinear reads it), since its part along the valley is the linearisation of a cost
    flat there (bench/lawlag.py --family share03, 500 Hz, L/R 2 ms, seed 2: ke_share ± 40 and
    J' ± 110 % where the whole valley, shares 0 to 1, spans J' 0.0073-0.011)."""
    if not (valley_free(free) and all(k in final.estimates for k in (*NAMES, "bv"))):
        return
    shim = SimpleNamespace(covariance=info, stats=final.stats)
    found = share_range(_cost(run, final.values), shim, final.estimates)
    if found is None:
        return
    point = {k: e.value for k, e in final.estimates.items()}
    ends = valley_points(point, found)
    mid = valley_points(point, [0.5 * (found[0] + found[1])])
    if len(ends) < 2 or not mid:
        return
    for k in NAMES:
        e = final.estimates[k]
        spread = abs(ends[-1][k] - ends[0][k]) / math.sqrt(12.0)  # uniform over the interval
        local = at_share(e.stderr, (rho or {}).get(k, math.nan))
        se = math.hypot(local, spread, mid[0][k] - e.value)
        if se > local:
            final.estimates[k] = dataclasses.replace(e, stderr=se)
    notes.append(
        f"ke_share between {found[0]:.2g} and {found[1]:.2g} fits as well (the back-EMF's share "
        "of bv trades with J and tau_e at equal linear response, only the friction and the dead "
        "zone tell them apart): J's, tau_e's and ke_share's standard errors are the root mean "
        "square distance from the fit's values to a share uniform over that interval, the local "
        f"fit's {'with the share held ' if rho else ''}combined (J = "
        f"{pm(final.estimates['J'], '.5g')}, ke_share = {pm(final.estimates['ke_share'])})")


def share_correlations(names: list[str], curv) -> dict[str, float]:
    """Each of J's, tau_e's and the share's local correlation with the share from the envelope
    Jacobian's ``(J'J)^-1`` ``curv`` over ``names`` (empty where it is missing)."""
    if curv is None or "ke_share" not in names:
        return {}
    b = names.index("ke_share")
    out = {}
    for k in NAMES:
        if k in names:
            a = names.index(k)
            den = math.sqrt(max(curv[a, a] * curv[b, b], 0.0))
            if den > 0 and math.isfinite(den):
                out[k] = float(curv[a, b] / den)
    return out


__all__ = ["VALLEY_STARTS", "dips", "share_correlations", "valley_errors", "valley_free",
           "valley_restart"]
