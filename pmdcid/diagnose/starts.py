"""Global starts for diagnose's refits: a coarse grid over the switching friction parameters.

The simulation-error cost is only piecewise smooth in bc and dz (breakaway and the dead-zone
switch move by whole internal steps) and has valleys where they trade off; a model fitted
without an effect the logs carry (a voltage limit, Stribeck friction) often sits in the wrong
valley, and a local refit from there stays in it. As fit-nonlinear does, a coarse grid over
(bc, dz), then over bv, with every other parameter at its start, puts the local refit in the
right valley. Costs a few dozen simulations of the logs.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.runtime.cpus import pmap

#: grid points per axis
GRID_N = 5
#: bv factors tried around the start
BV_FACTORS = (1 / 1.5, 1 / 1.2, 1.0, 1.2, 1.5)


def _axis(name: str, vals: dict[str, float], torque_scale: float) -> np.ndarray:
    bc = max(vals.get("bc", 0.0), 0.0)
    if name == "bc":
        return (np.geomspace(bc / 3, 3 * bc, GRID_N) if bc > 1e-3 * torque_scale
                else np.linspace(0.0, 0.3 * torque_scale, GRID_N))
    ref = max(vals.get("dz", 0.0), bc)
    top = 2.0 * ref if ref > 1e-3 * torque_scale else 0.3 * torque_scale
    return np.linspace(0.0, top, GRID_N)


def grid_start(problem, vals: dict[str, float], free, torque_scale: float,
               part: str = "fit") -> dict[str, float]:
    """Best of ``vals`` and a coarse grid over the free ones of bc, dz, then bv (chi-square of
    ``part``); returns the values to start a local refit from."""
    best = dict(vals)
    best_c = problem.cost(best, part)
    sw = [n for n in ("bc", "dz") if n in free]
    if sw:
        axes = np.meshgrid(*(_axis(n, vals, torque_scale) for n in sw), indexing="ij")
        # every trial sets all of ``sw``: it does not depend on the best point so far, so the
        # trials are simulated side by side and then compared in order, as one by one
        trials = [{**best, **dict(zip(sw, point, strict=True))}
                  for point in zip(*(a.ravel() for a in axes), strict=True)]
        best, best_c = lowest_trial(problem, trials, part, best, best_c)
    if "bv" in free and best.get("bv", 0.0) > 0:
        bv0 = best["bv"]
        trials = [{**best, "bv": bv0 * f} for f in BV_FACTORS]
        best, best_c = lowest_trial(problem, trials, part, best, best_c)
    return best


def lowest_trial(problem, trials, part, best, best_c):
    """The first trial of lowest ``part`` chi-square if below ``best_c``, else ``best``; the
    trials simulated on the spare CPUs (:func:`pmdcid.runtime.cpus.pmap`)."""
    costs = pmap(lambda v: problem.cost(v, part), trials)
    for trial, c in zip(trials, costs, strict=True):
        if c < best_c:
            best, best_c = trial, c
    return best, best_c


#: points of the profile scan of each switching parameter, and its half-width (relative)
PROFILE_N = 21
PROFILE_SPAN = 0.5


def profile_best(problem, vals: dict[str, float], free, part: str = "all") -> dict[str, float]:
    """Scan bc, then dz (those in ``free``) one at a time over +-50 % of their value (a dz at 0:
    from 0 to twice the breakaway torque), others held; returns the values with each moved to
    its best point.

    The cost is piecewise flat in a switching parameter: an event (a stair level's torque against
    the dead zone, a breakaway) flips between two of its values and the gradient sees nothing in
    between; a local fit can stop a few percent away from a cliff it never felt.
    """
    best = dict(vals)
    best_c = problem.cost(best, part)
    for name in ("bc", "dz"):
        if name not in free:
            continue
        v = best.get(name, 0.0)
        breakaway = max(best.get("bc", 0.0), 0.0) + max(best.get("fs", 0.0), 0.0)
        if name == "dz" and v < 0.05 * breakaway:
            # a dead zone at (or near) 0 has no gradient at all: scan from 0 to beyond the
            # breakaway torque
            xs = np.linspace(0.0, 2.0 * breakaway, 2 * PROFILE_N)
        elif v > 0:
            xs = v * np.linspace(1 - PROFILE_SPAN, 1 + PROFILE_SPAN, PROFILE_N)
        else:
            continue
        best, best_c = lowest_trial(problem, [{**best, name: float(x)} for x in xs], part, best,
                               best_c)
    return best


#: switching parameters a stalled refit scans (:func:`profile_best`)
PROFILED = ("bc", "dz")


def staged_fit(problem, start: dict[str, float], free, part: str, budget: int,
               typical_scale=None, limits=None):
    """``problem.fit`` of ``free`` from ``start`` within ``budget`` evaluations, in two halves
    around a profile scan when bc or dz is free.

    A refit that spends half its evaluations without converging is, as a rule, crawling along
    a switching parameter: the cost is piecewise flat in it, so the Gauss-Newton step sees only
    a local slope (on the demo logs dz moved 0.4 % per iteration for 40 iterations and a
    candidate's chi-square was still falling 3 % per 3 evaluations at the cap).
    :func:`profile_best` puts bc and dz at their best points and the refit resumes with the
    other half; the better of the two halves' results is returned.
    """
    if not any(p in free for p in PROFILED):
        return problem.fit(start, free, part, budget, typical_scale, limits)
    half = budget // 2
    fo = problem.fit(start, free, part, half, typical_scale, limits)
    if fo.stats.nfev < half:
        return fo
    more = problem.fit(profile_best(problem, fo.values, free, part), free, part, budget - half,
                       typical_scale, limits)
    more.stats.nfev += fo.stats.nfev
    return more if more.chi2[part] <= fo.chi2[part] else fo


def profile_stderr(problem, vals: dict[str, float], name: str, redchi: float,
                   span: float = 0.2, n: int = 41, zooms: int = 4) -> float:
    """Standard error [unit of ``name``] of a switching parameter from its profile (others
    held): the half-width at which the chi-square rises by ``redchi`` (one standard error),
    from a parabola through the scanned points within four times that rise of the best. The
    Jacobian's error is meaningless where the cost is flat between events (it comes out 0).
    Where fewer than five points fall in that band the scan is repeated ten times narrower
    around the best value (at most ``zooms`` times), so the result is the profile's width, not
    the scan's step (a floor of 1 % of the value was printed as a standard error before); NaN
    when even the finest scan cannot resolve it."""
    v = vals[name]
    if not v > 0:
        return float("nan")
    rise = max(redchi, 1.0)
    centre, half = v, span * v
    for _ in range(zooms + 1):
        xs = centre + np.linspace(-half, half, n if half == span * v else 21)
        xs = xs[xs > 0]
        c = np.array(pmap(lambda x: problem.chi2({**vals, name: float(x)})["all"], xs))
        band = c - c.min() <= 4.0 * rise
        if band.sum() >= 5:
            return _parabola_halfwidth(xs[band], c[band], rise)
        centre, half = float(xs[int(np.argmin(c))]), half / 10
    return float("nan")


def _parabola_halfwidth(x: np.ndarray, c: np.ndarray, rise: float) -> float:
    """Half-width at a rise of ``rise`` of the parabola fitted to (x, c); where the points do
    not curve upwards, half the spread of the points within that rise."""
    a = float(np.polyfit(x - x.mean(), c, 2)[0])
    if a > 0:
        return float(math.sqrt(rise / a))
    ok = x[c - c.min() <= rise]
    return float(0.5 * (ok.max() - ok.min()))


__all__ = ["grid_start", "lowest_trial", "profile_best", "profile_stderr", "staged_fit"]
