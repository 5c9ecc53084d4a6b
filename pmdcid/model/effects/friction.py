"""What the friction effects share: the logged speeds and the total friction over them.

A friction effect may take part of the paper's friction bc + bv·|omega| away (a negative drag, a
friction curve dipping below it), never all of it within the logged speeds: quadratic drag's and
the friction curve's refit bounds, and diagnose's check that a refit's total sliding friction
stays positive (:func:`lowest_friction`), read the same top speed.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.residual import ResidualContext

#: the top of the logged speeds: this quantile of the measured |omega| while moving (a few
#: noise spikes above it do not count as logged speeds)
TOP_QUANTILE = 0.999
#: a friction effect may take at most this share of the paper's friction bc + bv*|omega| away
#: at any logged speed (refit bounds): the total sliding friction stays positive
FRICTION_ROOM = 0.9
#: at least this many moving samples are needed to read the top logged speed
MIN_MOVING = 50


def moving_speeds(ctx: ResidualContext) -> np.ndarray:
    """Measured |omega| [rad/s] of every sample where the rotor turns (above 2 % of the typical
    speed), over all logs with a speed; measured, so the same for every model state."""
    out = [np.abs(lg.omega[np.isfinite(lg.omega)]) for lg in ctx.logs if lg.omega is not None]
    w = np.concatenate(out) if out else np.zeros(0)
    return w[w > 0.02 * ctx.speed_scale]


def paper_friction(ctx: ResidualContext, speed: float) -> float:
    """bc + bv*speed [N m] of the context's model (0 where it has none)."""
    bc, bv = (ctx.values.get(n, 0.0) for n in ("bc", "bv"))
    bc = bc if math.isfinite(bc) and bc > 0 else 0.0
    bv = bv if math.isfinite(bv) and bv > 0 else 0.0
    return bc + bv * speed


def lowest_friction(values: dict[str, float], top: float, n: int = 256) -> tuple[float, float]:
    """(smallest total sliding friction magnitude [N m], the signed speed [rad/s] where it is)
    over |omega| in (0, top], both directions, of the kernel's friction terms before its clamp:
    bc, bv, Stribeck, quadratic drag, dbv and the friction curve."""
    v = values.get
    speed = np.linspace(top / n, top, n)
    knots = [v(f"fcw{k + 1}", 0.0) for k in range(4)]
    fcs = [v(f"fc{k + 1}", 0.0) for k in range(3)]
    curve = (np.interp(speed, [0.0, *knots], [0.0, *fcs, 0.0], right=0.0)
             if knots[-1] > 0 else np.zeros_like(speed))
    fs, ws = v("fs", 0.0), v("ws", 1.0)
    strib = fs * np.exp(-(speed / ws) ** 2) if fs > 0 else 0.0
    best = (math.inf, 0.0)
    for d in (1.0, -1.0):
        mag = (v("bc", 0.0) + strib + v("bv", 0.0) * speed + v("bq", 0.0) * speed**2
               + d * v("dbv", 0.0) * speed + curve)
        j = int(np.argmin(mag))
        if mag[j] < best[0]:
            best = (float(mag[j]), d * float(speed[j]))
    return best


__all__ = ["FRICTION_ROOM", "MIN_MOVING", "TOP_QUANTILE", "lowest_friction", "moving_speeds",
           "paper_friction"]
