"""The dead zone read again once diagnose took the armature's lag (issue 24).

fit-nonlinear settled dz on a lumped model without its lag (fit-mechanical's steps had not
resolved it): the dead zone then acts on the applied voltage, flat up to the smallest level
driven, and was written as an interval or a point on that model. When diagnose takes the lag
(:mod:`pmdcid.diagnose.lawlag`) the dead zone acts on the lagged torque and that reading means
nothing: with the lag free dz, the back-EMF share and bc trade along a curved ridge whose events
move by internal steps, which a profile holding the others (:func:`~pmdcid.diagnose.final.
dead_zone_range`) cannot follow. Here dz is read on its refitted profile likelihood instead, as
fit-nonlinear reads it when the lag is free (:func:`pmdcid.identify.dead_zone.refit_profile`,
:func:`~pmdcid.identify.dead_zone.refit_interval`): the other free parameters re-minimised at
each dz.

- :func:`masked_on_profile`: whether some dz fits better than none (by two standard errors and
  0.1 % of the chi-square); where none does, the masked interval read on that profile (the
  model's dz kept where it lies inside, else the middle) and the others' spread across it.
  A dead zone the logs see is settled as without the lag (the model's where it fits as well).
- :func:`refitted_line`: dz's profile-likelihood interval; the values kept, dz's standard
  error a quarter of the interval's width where wider, and the others' widened by their
  spread along the interval (uniform over it), as the share's valley does
  (:mod:`pmdcid.identify.share_valley`).

Measured: ``python bench/lawlag.py --truths none --rates 500 --lags 2 --seeds 20``
(docs/identification.md, "Coverage on these motors").
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from pmdcid.errors import PmdcidError
from pmdcid.identify.dead_zone import REFIT_POINTS, REFIT_TOP, refit_interval, refit_profile
from pmdcid.identify.nonlinear import MASK_REL, crossing_upper

#: evaluations per refit along the profile (fit-nonlinear's profile refits use 60)
PROFILE_NFEV = 60


def lag_refits(run, free: list[str]) -> bool:
    """Whether dz is to be read on its refitted profile: diagnose took the lag (in a round,
    :mod:`.lawlag`, or in the final model's delay's place, :mod:`.lag`) and dz is free."""
    taken = getattr(run, "lag_taken", False) or getattr(run, "lag_late", False)
    return bool(taken) and "dz" in free and "tau_e" in free


def refitter(run, free: list[str], base: dict[str, float]):
    """``refit(dz, start)`` -> (chi-square of all data, values) with dz held at ``dz`` [N m]
    and the other ``free`` parameters refitted from ``start`` (the free ones; the rest at
    ``base``, the fit's values); None when the fit fails."""
    others = [p for p in free if p != "dz"]

    def refit(dz: float, start: dict[str, float]):
        try:
            fo = run.fit({**base, **start, "dz": dz}, others, "all", PROFILE_NFEV)
        except PmdcidError:
            return None
        return fo.chi2["all"], fo.values

    return refit


def threshold(run, fo) -> float:
    """Two standard errors' rise of the chi-square: 4 x the reduced chi-square (at least 4)."""
    n = max(run.problem.count("all") - len(fo.estimates), 1)
    return 4.0 * max(fo.chi2["all"] / n, 1.0)


def masked_on_profile(run, final, free: list[str]) -> tuple[float | None, dict[str, float]]:
    """dz checked on its refitted profile from 0 to :data:`REFIT_TOP` x max(bc, dz): (the
    masked interval's upper end [N m], the others' spread across it, :func:`spread_within`)
    where no dz fits better than none by more than two standard errors and 0.1 % of the
    chi-square; (None, {}) where one does (the logs see the dead zone) or the profile could
    not be fitted at dz = 0."""
    v = final.values
    thr = threshold(run, final)
    top = REFIT_TOP * max(v.get("bc", 0.0), v.get("dz", 0.0), 1e-12)
    dzs = np.linspace(0.0, top, REFIT_POINTS)
    cost, vals = refit_profile(refitter(run, free, v), v, dzs)
    low = float(cost.min())
    if not (math.isfinite(cost[0]) and math.isfinite(low)):
        return None, {}
    if cost[0] - low > max(thr, MASK_REL * low):
        return None, {}
    upper = crossing_upper(dzs, cost, thr)
    return upper, spread_within([x for d, x in zip(dzs, vals, strict=True)
                                 if x is not None and d <= upper], free)


def spread_within(points: list[dict[str, float]], free: list[str]) -> dict[str, float]:
    """Each free parameter's spread (its range over sqrt(12): uniform) across the refitted
    profile's ``points`` inside dz's masked interval: where the logs do not determine dz, the
    others move with it, and their local standard errors do not say so."""
    if len(points) < 2:
        return {}
    return {k: (max(p[k] for p in points) - min(p[k] for p in points)) / math.sqrt(12.0)
            for k in free if k != "dz" and all(k in p for p in points)}


def widen(estimates: dict, spread: dict[str, float]) -> None:
    """``estimates`` widened in place by ``spread`` in quadrature (:func:`spread_within`)."""
    for k, s in spread.items():
        e = estimates.get(k)
        if e is not None and s > 0 and math.isfinite(e.stderr):
            estimates[k] = dataclasses.replace(e, stderr=math.hypot(e.stderr, s))


def refitted_line(run, final, free: list[str], shim, notes: list[str]) -> None:
    """dz's interval on its refitted profile (:func:`refit_interval`; ``shim``: the fit's
    estimates, envelope curvature and held covariance as the profile line reads them):
    ``final``'s standard errors widened in place, dz's to a quarter of the interval's width,
    the others' by their spread along it. The values stay the fit's, as
    :func:`~pmdcid.diagnose.final.dead_zone_line` keeps them: moved to the interval's middle,
    the L298N rig's dz went from 2.4 to 5.1 V (its commands never fall below 6 V: a dead zone
    up to there only delays the onset), the drive's drop it warns of with it."""
    refit = refitter(run, free, dict(final.values))
    moved, why = refit_interval(refit, shim)
    if not moved:
        return
    was = final.estimates["dz"]
    spread = _spread(refit, final.values, moved, was, moved["dz"])
    for k, e in moved.items():
        old = final.estimates[k]
        se = e.stderr if k == "dz" else math.hypot(old.stderr, spread.get(k, 0.0))
        final.estimates[k] = dataclasses.replace(old, stderr=max(se, old.stderr))
    if why:  # the values written are the fit's: the note says so, not the interval's middle's
        notes.append(
            f"dz = {was.value:.5g} ± {final.estimates['dz'].stderr:.2g}: the fit's value, its "
            "standard error a quarter of its profile-likelihood interval's width (the other "
            "parameters refitted at each dead zone; the cost is a staircase in dz, flat between "
            f"the dead zone's events; the interval's middle {moved['dz'].value:.5g}, the local "
            f"fit's error {was.stderr:.2g}); the armature's lag taken by diagnose, dz read with it")


def _spread(refit, vals, moved, old, new) -> dict[str, float]:
    """Each other parameter's spread (its range over sqrt(12): uniform) across dz's interval
    (the new estimate +- 2 of its standard errors), from refits at the interval's ends."""
    if not new.stderr > old.stderr:
        return {}
    start = {**vals, **{k: e.value for k, e in moved.items()}}
    ends = [refit(max(new.value + s * 2.0 * new.stderr, 0.0), start) for s in (-1.0, 1.0)]
    if any(e is None for e in ends):
        return {}
    (_, lo), (_, hi) = ends
    return {k: abs(hi[k] - lo[k]) / math.sqrt(12.0) for k in moved if k != "dz"
            and k in lo and k in hi}


__all__ = ["lag_refits", "masked_on_profile", "refitted_line", "spread_within", "widen"]
