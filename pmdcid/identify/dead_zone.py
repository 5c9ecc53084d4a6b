"""The dead zone's standard error from its profile: the cost is a staircase in dz.

The kernel places the dead zone's switching at whole internal steps (docs/identification.md,
"Why this method"), so the cost along dz is flat between two placements of an event and jumps
where an event moves by one internal step: a staircase on a smooth envelope. The covariance
comes from the envelope's slope (central differences over 1 %), which says how fast the
envelope rises, not how wide its flat floor is, and the local stage stops anywhere on that
floor. On the paper's motor (bench/stderr_coverage.py, seeds 900-1099) the floor along dz's
profile line was 2 to 7 of the covariance's (logs' own) standard errors wide, the estimates
spread 2.2x more than the printed errors, and 72 % of the seeds held the truth within 2 of
them.

:func:`dead_zone_interval` reads the profile-likelihood interval instead: the cost along dz
with the other free parameters following their conditional optimum (by the chi-square's own
curvature, :attr:`SimFitResult.curvature`; on those seeds this line agreed with refitting J,
bv, bc at each dz to a unit of chi-square), the interval where it stays within two standard
errors' rise of its lowest (the rise the envelope would have over two of dz's own standard
errors: 4 x the reduced chi-square for white residuals). The estimate is moved to that
interval's middle (every free parameter on the line: the fit's own point is one arbitrary
point of a flat floor), dz's standard error is a quarter of the interval's width where that
exceeds the covariance's logs' part, the held parameters' (R, L) part
(:attr:`SimFitResult.held_cov`) added back in quadrature. Where the cost is a smooth parabola
the interval is +-2 of the covariance's standard errors about the fit's point and nothing
changes. Measured on those 200 seeds: the truth within 2 standard errors in 94 % (RMS of
the ratio 1.14; bench/stderr_coverage.py, docs/identification.md's coverage table).

With a lumped model's electrical lag free (tau_e, ke_share) the line is no profile: dz, the
back-EMF share and bc trade along a curved ridge whose events move by internal steps.
:func:`refit_profile` re-minimises the other free parameters at each dz (each fit started from
its neighbour's solution), :func:`refit_interval` reads dz's interval on that profile (its
lower convex hull: the refitted points are rough), and fit-nonlinear's masked check uses it
(bench/lawlag.py: docs/identification.md, "Coverage on these motors").
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.fit.results import Estimate
from pmdcid.identify.share_valley import lower_hull
from pmdcid.model.effects import bounds_of

#: the scan along the profile line: half-width in the covariance's standard errors of dz (the
#: logs' own part), and its points; a scan whose edge is still inside the interval is
#: repeated :data:`WIDEN` times wider, once
SPAN = 8.0
POINTS = 65
WIDEN = 4.0
#: a move of the estimate to the interval's middle said in words beyond this many of dz's own
#: standard errors
MOVED = 0.5
#: the profile interval's half-width in standard errors on a smooth envelope (its threshold:
#: the chi-square's rise over that many, :func:`profile_line`)
TWO_SE = 2.0


def profile_line(fit, name: str = "dz"):
    """(free names, values, direction, standard error, threshold) of the profile line through
    ``fit``'s solution. The direction: per unit of ``name``'s own standard error (the logs'
    part: the fit's covariance less what its held parameters add), the others moving to their
    conditional optimum by the criterion's own curvature (``fit.curvature``, the data rows'
    ``(J'J)^-1``, with the prior rows' information where the fit had priors: the profile's
    direction; the sandwich covariance's regression would not be one where the residual is
    correlated). The threshold: the chi-square's rise over two of
    those standard errors on the envelope, ``4 se^2 / curvature[j, j]`` (4 x the reduced
    chi-square for white residuals). None when either is not positive and finite."""
    free = list(fit.estimates)
    curv = getattr(fit, "curvature", None)
    if name not in free or curv is None or curv.shape != (len(free), len(free)):
        return None
    if not np.all(np.isfinite(curv)):
        return None
    curv = _with_priors(curv, fit, free)
    j = free.index(name)
    se = fit.estimates[name].stderr
    var = se**2 - _held_var(fit, j)
    h = curv[j, j]
    if not (h > 0 and math.isfinite(var) and var > 0):
        return None
    sd = math.sqrt(var)
    x = np.array([fit.estimates[k].value for k in free])
    return free, x, curv[:, j] / h * sd, sd, TWO_SE**2 * var / h


def _with_priors(curv: np.ndarray, fit, free) -> np.ndarray:
    """The whole criterion's inverse curvature: the data rows' ``(J'J)^-1`` with the prior
    rows' information added (``(Hd + w^2 P)^-1``; ``curv`` itself without priors), inverted on
    the correlation scale (entries of very different sizes)."""
    rows = [(free.index(n), s) for n, (_, s) in fit.priors.items() if n in free and s > 0]
    if not rows:
        return curv
    dg = np.sqrt(np.clip(np.diag(curv), 1e-300, None))
    h = np.linalg.pinv(curv / np.outer(dg, dg))  # Hd on the scaled axes
    for i, s in rows:
        h[i, i] += (fit.prior_weight * dg[i] / s) ** 2
    return np.linalg.pinv(h) * np.outer(dg, dg)


def _prior_cost(fit, sets) -> np.ndarray:
    """The prior rows' part of the criterion at each set (0 without priors)."""
    w = fit.prior_weight
    return np.array([sum((w * (s[n] - m) / sd) ** 2 for n, (m, sd) in fit.priors.items()
                         if n in s and sd > 0) for s in sets])


def _scan(cost, fit, free, x, d, j, span):
    """Cost rise along the line at ``POINTS`` steps over +-``span`` (every free parameter kept
    within its bounds, dz >= 0 among them; the points beyond get an infinite cost: a follower
    such as bv led below 0 made a model its own simulate refuses) and the cost at the
    solution."""
    a = np.linspace(-span, span, POINTS)
    lo, hi = (np.array(b, float) for b in zip(*(bounds_of(n) for n in free), strict=True))
    pts = x[None, :] + a[:, None] * d[None, :]
    ok = np.all((pts >= lo) & (pts <= hi), axis=1) & (pts[:, j] >= 0)
    sets = [dict(zip(free, x, strict=True))] + [dict(zip(free, x + s * d, strict=True))
                                               for s in a[ok]]
    c = np.asarray(cost(sets), float) + _prior_cost(fit, sets)
    rise = np.full(len(a), np.inf)
    rise[ok] = c[1:] - c[0]
    return a, rise


def dead_zone_interval(cost, fit, name: str = "dz") -> tuple[dict[str, Estimate], str]:
    """The profile-likelihood interval of ``name`` (module docstring): (estimates to write in
    place of ``fit``'s — every free parameter moved to the interval's middle on the profile
    line, their own standard errors kept, ``name``'s the larger of a quarter of the interval's
    width and the covariance's logs' part, with the held parameters' part added — and the
    words for the notes, empty when the estimate moved less than :data:`MOVED` of its own
    standard errors and the error did not widen); ({}, "") when no line exists.
    ``cost(sets)``: the chi-square of each parameter set (dicts of the free ones)."""
    line = profile_line(fit, name)
    if line is None:
        return {}, ""
    free, x, d, sd, thr = line
    j = free.index(name)
    span = SPAN
    for _ in range(2):
        a, rise = _scan(cost, fit, free, x, d, j, span)
        low = min(0.0, float(rise.min()))
        inside = a[rise - low <= thr]
        if len(inside) == 0 or (inside.min() > a[0] and inside.max() < a[-1]):
            break
        span *= WIDEN
    if len(inside) == 0:
        return {}, ""
    lo, hi = float(inside.min()), float(inside.max())
    mid = 0.5 * (lo + hi)
    if not rise[int(np.argmin(np.abs(a - mid)))] - low <= thr:
        mid = float(inside[int(np.argmin(np.abs(inside - mid)))])  # a gap: the nearest inside
    width = 0.25 * (hi - lo)  # the 2-standard-error interval's half-width, halved [sd]
    est = fit.estimates[name]
    se = math.sqrt(max(width, 1.0) ** 2 * sd ** 2 + _held_var(fit, j))
    out = {k: Estimate(k, float(x[i] + mid * d[i]), fit.estimates[k].stderr,
                       fit.estimates[k].unit) for i, k in enumerate(free)}
    out[name] = Estimate(name, out[name].value, se, est.unit)
    if width <= 1.0 and abs(mid) <= MOVED:
        return out, ""
    why = (f"{name} = {out[name].value:.5g} ± {se:.2g}: the middle of its profile-likelihood "
           "interval, ± a quarter of its width (the held parameters' part added; never narrower "
           f"than the covariance's: the local fit gave {est.value:.5g} ± {est.stderr:.2g}); the "
           f"cost is a staircase in {name}, flat between the dead zone's events, which the "
           "simulation places per internal step")
    return out, why


#: the refitted profile's reach and points where the held profile calls dz masked
#: (:func:`refit_profile`): dz from 0 to this many times the larger of bc and dz, evenly spaced
REFIT_TOP = 3.0
REFIT_POINTS = 9
#: the refitted profile's points across +-:data:`SPAN` standard errors (:func:`refit_interval`)
REFIT_SCAN = 13


def refit_profile(refit, start: dict[str, float], dzs: np.ndarray,
                  slope: dict[str, float] | None = None):
    """The profile likelihood of dz at the dead zones ``dzs`` [N m] (ascending): at each, the
    other free parameters re-minimised (``refit(dz, start)`` -> (chi-square, values); None where
    that fit failed), each fit started from its neighbour's solution, the walk starting at
    ``start`` (its own dz: the fit's solution) and stepping away from it on both sides. A
    profile whose other parameters are held cannot follow the ridge along which dz, the
    back-EMF share and bc trade; this one does. ``slope``: how far each other parameter moves
    per unit of dz (the profile line's), added to the neighbour's solution as the next start
    (a predictor step); none when not given. Returns (chi-square at each, values at each):
    infinite chi-square where the fit failed or dz < 0."""
    n = len(dzs)
    cost = np.full(n, np.inf)
    vals: list[dict | None] = [None] * n
    k0 = int(np.argmin(np.abs(dzs - start.get("dz", 0.0))))
    for order in (range(k0, n), range(k0 - 1, -1, -1)):
        here, at = dict(start), start.get("dz", 0.0)
        for k in order:
            step = float(dzs[k]) - at
            guess = {n: v + (slope or {}).get(n, 0.0) * step for n, v in here.items()}
            got = refit(float(dzs[k]), guess) if dzs[k] >= 0 else None
            if got is None:
                continue
            cost[k], vals[k] = got
            here, at = {**here, **vals[k]}, float(dzs[k])
    return cost, vals


def refit_interval(refit, fit, name: str = "dz") -> tuple[dict[str, Estimate], str]:
    """:func:`dead_zone_interval` on the profile likelihood itself: at :data:`REFIT_SCAN`
    dead zones across +-:data:`SPAN` of dz's own standard errors (widened :data:`WIDEN` times
    once when the interval reaches an edge) the other free parameters are re-minimised
    (:func:`refit_profile`), where the line holds them on their linear regression: along the
    ridge where dz, the back-EMF share and bc trade (a lumped model with its electrical lag
    free) the line leaves the ridge and the local stage stops in one of the staircase's dips.
    The estimates: every free parameter at the refitted point nearest the interval's middle,
    their standard errors kept, dz's a quarter of the interval's width where wider than the
    covariance's (the held parameters' part added); with the words for the notes, empty when
    dz moved less than :data:`MOVED` of its standard errors and its error did not widen.
    ({}, "") without a line or a finite profile."""
    line = profile_line(fit, name)
    if line is None:
        return {}, ""
    free, x, d, sd, thr = line
    j = free.index(name)
    start = dict(zip(free, x, strict=True))
    slope = {n: d[i] / d[j] for i, n in enumerate(free) if i != j}
    a, cost, vals = np.zeros(0), np.zeros(0), []
    for span in (SPAN, SPAN * WIDEN):
        more = np.linspace(-span, span, REFIT_SCAN)
        more = more[np.min(np.abs(more[:, None] - a[None, :]), axis=1, initial=np.inf) > 1e-9]
        c, v = refit_profile(refit, start, x[j] + more * sd, slope)
        a, cost, vals = np.append(a, more), np.append(cost, c), vals + v
        ok = np.flatnonzero(np.isfinite(cost))
        if not len(ok):
            return {}, ""
        o = ok[np.argsort(a[ok], kind="stable")]
        lo, hi = band(a[o], lower_hull(a[o], cost[o]), thr)
        if lo > -span and hi < span:
            break
    k = int(o[np.argmin(np.abs(a[o] - 0.5 * (lo + hi)))])
    width = 0.25 * (hi - lo)  # the 2-standard-error interval's half-width, halved [sd]
    est = fit.estimates[name]
    se = math.sqrt(max(width, 1.0) ** 2 * sd ** 2 + _held_var(fit, j))
    at = {**start, **vals[k], name: float(x[j] + a[k] * sd)}
    out = {n: Estimate(n, float(at[n]), fit.estimates[n].stderr, fit.estimates[n].unit)
           for n in free}
    out[name] = Estimate(name, out[name].value, max(se, est.stderr), est.unit)
    if width <= 1.0 and abs(a[k]) <= MOVED:
        return out, ""
    why = (f"{name} = {out[name].value:.5g} ± {out[name].stderr:.2g}: the middle of its "
           "profile-likelihood interval (the other parameters refitted at each dead zone), ± a "
           "quarter of its width (never narrower than the covariance's: the local fit gave "
           f"{est.value:.5g} ± {est.stderr:.2g}); the cost is a staircase in {name}, flat "
           "between the dead zone's events, which the simulation places per internal step")
    return out, why


def band(a: np.ndarray, env: np.ndarray, thr: float) -> tuple[float, float]:
    """(low, high) ``a`` (ascending) where the convex ``env`` lies within ``thr`` of its lowest,
    the edges read between the points linearly (the outermost points when it never leaves)."""
    rise = env - env.min()
    inside = np.flatnonzero(rise <= thr)
    i, k = int(inside.min()), int(inside.max())
    lo, hi = float(a[i]), float(a[k])
    if i > 0:
        lo -= (a[i] - a[i - 1]) * (thr - rise[i]) / max(rise[i - 1] - rise[i], 1e-300)
    if k < len(a) - 1:
        hi += (a[k + 1] - a[k]) * (thr - rise[k]) / max(rise[k + 1] - rise[k], 1e-300)
    return lo, hi


def _held_var(fit, j: int) -> float:
    held = getattr(fit, "held_cov", None)
    return float(held[j, j]) if held is not None and held[j, j] > 0 else 0.0


__all__ = ["dead_zone_interval", "profile_line", "refit_interval", "refit_profile"]
