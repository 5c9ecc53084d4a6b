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
with the other free parameters following their conditional optimum (their regression on dz in
the logs' own covariance, without the held parameters' part, :attr:`SimFitResult.held_cov`:
the profile's direction at the held values; on those seeds it agreed with refitting J, bv, bc
at each dz to a unit of chi-square), the interval where it stays within ``4 x`` the reduced
chi-square (x the correlated-residual inflation squared) of its lowest: two standard errors.
The estimate is moved to that interval's middle (every free parameter on the line: the fit's
own point is one arbitrary point of a flat floor), dz's standard error is a quarter of the
interval's width where that exceeds the covariance's logs' part, the held parameters' (R, L)
part added back in quadrature. Where the cost is a smooth parabola the interval is +-2 of the
covariance's standard errors about the fit's point and nothing changes. Measured on those 200
seeds: the truth within 2 standard errors in 96 % (bench/stderr_coverage.py;
docs/identification.md's coverage table).
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.fit.results import Estimate

#: the scan along the profile line: half-width in the covariance's standard errors of dz (the
#: logs' own part), and its points; a scan whose edge is still inside the interval is
#: repeated :data:`WIDEN` times wider, once
SPAN = 8.0
POINTS = 65
WIDEN = 4.0
#: a move of the estimate to the interval's middle said in words beyond this many of dz's own
#: standard errors
MOVED = 0.5
#: the profile interval's threshold in standard errors: a rise of ``TWO_SE**2`` x the reduced
#: chi-square (x the inflation squared) above the line's lowest point
TWO_SE = 2.0


def profile_line(fit, name: str = "dz"):
    """(free names, values, direction, standard error) of the profile line through ``fit``'s
    solution: per unit of ``name``'s own (logs') standard error, the others moving by their
    regression on it in the logs' covariance (the fit's covariance less what its held
    parameters add). None when that covariance has no positive variance for ``name``."""
    free = list(fit.estimates)
    if name not in free:
        return None
    se = np.array([fit.estimates[k].stderr for k in free])
    x = np.array([fit.estimates[k].value for k in free])
    if not np.all(np.isfinite(se) & (se > 0)):
        return None
    corr = np.array([[1.0 if a == b else fit.correlation(a, b) for b in free] for a in free])
    cov = np.nan_to_num(corr) * np.outer(se, se)
    held = getattr(fit, "held_cov", None)
    data = cov - held if held is not None and held.shape == cov.shape else cov
    j = free.index(name)
    if not data[j, j] > 0:
        return None
    sd = math.sqrt(data[j, j])
    return free, x, data[:, j] / data[j, j] * sd, sd


def threshold(fit) -> float:
    """Two standard errors' rise of the chi-square: ``4 x`` the reduced chi-square (at least 1)
    x the correlated-residual inflation squared (the units the covariance counts in)."""
    cov = fit.covariance
    infl = cov.inflation if cov is not None and cov.inflation > 1 else 1.0
    return TWO_SE ** 2 * max(fit.stats.redchi, 1.0) * infl ** 2


def _scan(cost, free, x, d, j, span):
    """Cost rise along the line at ``POINTS`` steps over +-``span`` (dz kept >= 0; the points
    below it get an infinite cost) and the cost at the solution."""
    a = np.linspace(-span, span, POINTS)
    ok = x[j] + a * d[j] >= 0
    sets = [dict(zip(free, x, strict=True))] + [dict(zip(free, x + s * d, strict=True))
                                               for s in a[ok]]
    c = np.asarray(cost(sets), float)
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
    free, x, d, sd = line
    j = free.index(name)
    thr = threshold(fit)
    span = SPAN
    for _ in range(2):
        a, rise = _scan(cost, free, x, d, j, span)
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


def _held_var(fit, j: int) -> float:
    held = getattr(fit, "held_cov", None)
    return float(held[j, j]) if held is not None and held[j, j] > 0 else 0.0


__all__ = ["dead_zone_interval", "profile_line", "threshold"]
