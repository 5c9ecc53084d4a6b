"""The dead zone's standard error from its profile: the cost is a staircase in dz.

The kernel places the dead zone's switching at whole internal steps (docs/identification.md,
"Why this method"), so the cost along dz is flat between two event placements and jumps where
an event moves by one internal step: a staircase on a smooth envelope. The covariance comes
from the envelope's slope (central differences over 1 %), which says how fast the envelope
rises, not how wide its flat floor is, and the local stage stops anywhere on that floor. On
the paper's motor (bench/stderr_coverage.py, seeds 900-1099) the floor along dz's profile line
was 2 to 7 of the covariance's standard errors wide, the estimates spread 2.2x more than the
printed errors, and 71 % of the seeds held the truth within 2 of them.

:func:`dead_zone_interval` reads the profile-likelihood interval instead: the cost along dz
with the other free parameters following their conditional optimum (their regression on dz
in the logs' own covariance, without the held parameters' part: the profile's direction at the
held values), the interval where it stays within ``4 x`` the reduced chi-square (x the
correlated-residual inflation squared) of its lowest (two standard errors), the estimate moved
to that interval's middle (the same cost within the threshold, every parameter on the line),
its standard error a quarter of the interval's width, with the held parameters' part added
back. Never narrower than the covariance's. The result says so in words.
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
    line, ``name`` with its interval's standard error — and one line for the warnings); ({},
    "") when the covariance's own standard error is already at least as wide or no line
    exists. ``cost(sets)``: the chi-square of each parameter set (dicts of the free ones)."""
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
    width = 0.25 * (hi - lo) * sd  # the 2-standard-error interval's half-width, halved
    est = fit.estimates[name]
    if not width > _data_part(est.stderr, fit, j):
        return {}, ""
    mid = 0.5 * (lo + hi)
    if not rise[int(np.argmin(np.abs(a - mid)))] - low <= thr:
        mid = float(inside[int(np.argmin(np.abs(inside - mid)))])  # a gap: the nearest inside
    held = _held_var(fit, j)
    out = {k: Estimate(k, float(x[i] + mid * d[i]), fit.estimates[k].stderr,
                       fit.estimates[k].unit) for i, k in enumerate(free)}
    se = math.sqrt(width ** 2 + held)
    out[name] = Estimate(name, out[name].value, se, est.unit)
    why = (f"{name}'s standard error is its profile's: the cost along {name} (the others "
           f"following it) is flat between the dead zone's events, placed per internal step, "
           f"over {(hi - lo) / 2:.2g} of the covariance's standard errors either side; the "
           f"value is the middle of that interval and its ± a quarter of its width "
           f"({se:.2g}, the covariance's {est.stderr:.2g})")
    return out, why


def _held_var(fit, j: int) -> float:
    held = getattr(fit, "held_cov", None)
    return float(held[j, j]) if held is not None and held[j, j] > 0 else 0.0


def _data_part(stderr: float, fit, j: int) -> float:
    """The logs' own part of a standard error (the held parameters' part taken out)."""
    return math.sqrt(max(stderr ** 2 - _held_var(fit, j), 0.0))


__all__ = ["dead_zone_interval", "profile_line", "threshold"]
