"""Global starts for diagnose's refits: a coarse grid over the switching friction parameters.

The simulation-error cost is only piecewise smooth in bc and dz (breakaway and the dead-zone
switch move by whole internal steps) and has valleys where they trade off; a model fitted
without an effect the logs carry (a voltage limit, Stribeck friction) often sits in the wrong
valley, and a local refit from there stays in it. As fit-nonlinear does, a coarse grid over
(bc, dz), then over bv, with every other parameter at its start, puts the local refit in the
right valley. Costs a few dozen simulations of the logs.
"""

from __future__ import annotations

import numpy as np

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
    best_c = problem.chi2(best)[part]
    sw = [n for n in ("bc", "dz") if n in free]
    if sw:
        axes = np.meshgrid(*(_axis(n, vals, torque_scale) for n in sw), indexing="ij")
        for point in zip(*(a.ravel() for a in axes), strict=True):
            trial = {**best, **dict(zip(sw, point, strict=True))}
            c = problem.chi2(trial)[part]
            if c < best_c:
                best, best_c = trial, c
    if "bv" in free and best.get("bv", 0.0) > 0:
        bv0 = best["bv"]
        for f in BV_FACTORS:
            trial = {**best, "bv": bv0 * f}
            c = problem.chi2(trial)[part]
            if c < best_c:
                best, best_c = trial, c
    return best


__all__ = ["grid_start"]
