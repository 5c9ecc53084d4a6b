"""Speed-dependent friction that follows no named law: friction gains sign(omega)*c(|omega|).

c is piecewise linear through (0, 0), (fcw_k, fc_k) for k = 1..3 and (fcw4, 0), zero beyond fcw4
(the paper's bc + bv*|omega| continues past the logged speeds). The knot speeds are 0.15, 0.4,
0.7 and 1 times the top logged |omega| (its 99.9 % quantile while moving), written in the model
file and held; the knot values are fitted, each at least -0.9 times bc + bv*fcw_k so the total
friction stays positive over the logged speeds. Zero at omega = 0 (breakaway unchanged), the
same in both directions. Signature: a speed residual that is a smooth function of |omega| (e.g.
friction rising then flattening: the speed per unit torque grows with speed) which quadratic
drag, Stribeck or viscous asymmetry do not follow. diagnose prefers those named laws when they
explain the residual about as well.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects.friction import (
    FRICTION_ROOM,
    MIN_MOVING,
    TOP_QUANTILE,
    moving_speeds,
    paper_friction,
)
from pmdcid.model.effects.probes import torque_probe
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import Probe, ResidualContext
from pmdcid.model.spec import ParamSpec

#: the parameters: knot speeds fcw1..fcw4 [rad/s] (placed by the logged speeds and held) and the
#: friction added at the first three fc1..fc3 [N m] (0 at the last)
CURVE_SPEEDS = tuple(f"fcw{k}" for k in range(1, 5))
CURVE_VALUES = tuple(f"fc{k}" for k in range(1, 4))
#: inner knot speeds, as fractions of the top logged speed (the last knot); denser at low speed,
#: where friction changes fastest. Not quantiles of |omega|: those crowd the knots where the
#: logs dwell (step plateaus, slow ramps) and leave the top of the speed range to one long
#: segment
CURVE_FRACTIONS = (0.15, 0.4, 0.7)


def curve_knots(ctx: ResidualContext) -> list[float]:
    """The knot speeds [rad/s], increasing: the top logged speed (the
    :data:`~pmdcid.model.effects.friction.TOP_QUANTILE` of the moving speeds) times
    :data:`CURVE_FRACTIONS`, and the top itself; [] when too few samples move."""
    w = moving_speeds(ctx)
    if len(w) < MIN_MOVING:
        return []
    top = float(np.quantile(w, TOP_QUANTILE))
    return [f * top for f in CURVE_FRACTIONS] + [top] if top > 0 else []


def _knot_params(knots: list[float]) -> dict[str, float]:
    return {f"fcw{k + 1}": w for k, w in enumerate(knots)}


def signature(ctx: ResidualContext) -> list[Probe]:
    """One probe: a small bump of friction at each inner knot in turn (one column per knot)."""
    knots = curve_knots(ctx)
    if not knots:
        return []
    size = torque_probe(ctx)
    speeds = _knot_params(knots)
    cols = [{**speeds, f"fc{k + 1}": size} for k in range(len(knots) - 1)]
    return [Probe(cols, "knots " + ", ".join(f"{w:.3g}" for w in knots) + " rad/s")]


def limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """fc_k [N m] at least -0.9 (bc + bv fcw_k): the curve never takes away more than 90 % of
    the paper's friction at a knot, so with bc, bv >= 0 the total stays positive over the
    logged speeds (piecewise linear between knots, 0 at 0 and from the last knot on)."""
    out = {}
    for k, w in enumerate(curve_knots(ctx)[:-1]):
        floor = paper_friction(ctx, w)
        if floor > 0:
            out[f"fc{k + 1}"] = (-FRICTION_ROOM * floor, math.inf)
    return out


def guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """Knot values from the regression on the bumps, raised to the limits' floor."""
    cols = probe.columns
    out = {n: v for n, v in cols[0].items() if n.startswith("fcw")}
    lim = limits(ctx)
    for k, col in enumerate(cols):
        name = f"fc{k + 1}"
        v = float(coefs[k]) * col[name]
        if not math.isfinite(v):
            return None
        out[name] = max(v, 0.5 * lim[name][0]) if name in lim else v
    if not any(out[f"fc{k + 1}"] != 0.0 for k in range(len(cols))):
        return None
    return out


EFFECT = Effect(
    "friction_curve", __doc__,
    tuple(ParamSpec(n, "rad/s", f"friction curve knot speed {n[-1]} (from the logged speeds)",
                    0.0, 0.0, 1e6) for n in CURVE_SPEEDS)
    + tuple(ParamSpec(n, "N m", f"friction added at knot speed fcw{n[-1]}", 0.0, -1e6, 1e6)
            for n in CURVE_VALUES),
    "mechanical",
    ("bv", "bc"),
    signature=signature,
    guess=guess,
    held=CURVE_SPEEDS,
    limits=limits,
    size_params=CURVE_VALUES,
    record="steady speeds spanning the range, in logs of their own (a staircase of levels)",
)
