"""Viscous friction that depends on the direction of motion: friction gains dbv*|omega|.

That is bv + dbv moving forward and bv - dbv backward (a worn or unevenly preloaded screw, seals
that drag more one way). Signature: speed residual of one sign in both directions that grows
with |omega| (a torque offset's residual does not grow with speed); plateau speeds differ
between directions by more than Coulomb friction explains.
"""

from __future__ import annotations

import math

from pmdcid.model.effects.probes import PROBE, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.model.spec import ParamSpec


def probe_size(ctx: ResidualContext) -> float:
    """[N m s/rad] a viscous difference giving a few percent of the friction torque at the
    typical speed."""
    return PROBE * ctx.torque_scale / ctx.speed_scale


def limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """|dbv| below 0.9 bv: the viscous friction stays positive in both directions."""
    bv = ctx.values.get("bv", math.nan)
    if not (math.isfinite(bv) and bv > 0):
        return {}
    return {"dbv": (-0.9 * bv, 0.9 * bv)}


EFFECT = Effect(
    "viscous_asymmetry", __doc__,
    (ParamSpec("dbv", "N m s/rad", "direction-dependent part of the viscous friction", 0.0,
               -1e6, 1e6),),
    "mechanical",
    ("bv", "tau0"),
    **linear("dbv", probe_size, positive=False),
    limits=limits,
    record="steady speeds in both directions at several levels",
)
