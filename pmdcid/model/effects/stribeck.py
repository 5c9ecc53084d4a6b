"""Static friction above the Coulomb level that falls off with speed.

Friction gains fs*exp(-(omega/ws)^2)*sign(omega); breakaway torque bc + fs. Signature: late
breakaway and a speed deficit concentrated at low |omega|, vanishing at high speed.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects.probes import torque_probe
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import Probe, ResidualContext
from pmdcid.model.spec import ParamSpec

#: Stribeck speeds tried (the speed enters non-linearly), as fractions of the typical speed
STRIBECK_SPEEDS = (0.02, 0.06, 0.2)


def signature(ctx: ResidualContext) -> list[Probe]:
    fs = torque_probe(ctx)
    return [Probe([{"fs": fs, "ws": f * ctx.speed_scale}], f"ws={f * ctx.speed_scale:.3g}")
            for f in STRIBECK_SPEEDS]


def guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    col = probe.columns[0]
    fs = float(coefs[0]) * col["fs"]
    if not math.isfinite(fs) or fs <= 0:
        return None
    return {"fs": fs, "ws": col["ws"]}


def limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """ws [rad/s] below half the typical speed: a Stribeck curve that decays only at the top
    speeds is Coulomb friction with a speed-squared correction (quadratic drag's signature)."""
    return {"ws": (1e-3 * ctx.speed_scale, 0.5 * ctx.speed_scale)}


EFFECT = Effect(
    "stribeck", __doc__,
    (ParamSpec("fs", "N m", "static friction above Coulomb", 0.0, 0.0, 1e6),
     ParamSpec("ws", "rad/s", "Stribeck speed", 1.0, 1e-6, 1e6)),
    "mechanical",
    ("bc", "dz"),
    signature=signature,
    guess=guess,
    limits=limits,
    record="slow reversals or breakaways from rest in a log of their own (a slow triangle)",
)
