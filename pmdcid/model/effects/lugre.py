"""LuGre dynamic friction: bristles of deflection z (a kernel state) replace the stick-slip logic.

dz/dt = omega - sigma0*|omega|*z/g(omega), g = bc + fs*exp(-(omega/ws)^2) (the Coulomb/Stribeck
level, from the model's bc and stribeck); friction sigma0*z + sigma1*dz/dt + bv*omega (+ quadratic
drag, viscous asymmetry). Below breakaway the rotor springs back: a presliding angle of about
torque/sigma0, with hysteresis on a reversal; at constant speed the static curve
g(omega) sign(omega) + bv*omega. Signature: angle creeping under torques below breakaway (needs
an angle sampled well above sqrt(sigma0/J)/(2 pi) Hz and resolved below bc/sigma0); smooth, not
stepped, breakaway. Not screened by default (--effect lugre).
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import Probe, ResidualContext
from pmdcid.model.spec import ParamSpec

#: presliding displacements tried [rad] (the stiffness enters non-linearly): the breakaway
#: torque moves the rotor this far
PRESLIDING = (1e-4, 1e-3, 1e-2)


def critical_damping(sigma0: float, J: float) -> float:
    """[N m s/rad] micro-damping making the presliding spring critically damped: 2 sqrt(sigma0 J)
    (J [kg m^2] unknown or not positive: none)."""
    if not (math.isfinite(J) and J > 0):
        return 0.0
    return 2.0 * math.sqrt(sigma0 * J)


def signature(ctx: ResidualContext) -> list[Probe]:
    """The full effect at a few bristle stiffnesses sigma0 = breakaway / displacement."""
    breakaway = ctx.values.get("bc", 0.0) + ctx.values.get("fs", 0.0)
    if not (math.isfinite(breakaway) and breakaway > 0):
        breakaway = ctx.torque_scale
    J = ctx.values.get("J", math.nan)
    out = []
    for x in PRESLIDING:
        s0 = breakaway / x
        out.append(Probe([{"sigma0": s0, "sigma1": critical_damping(s0, J)}], f"x={x:g} rad"))
    return out


def guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """The probe is the full effect at that stiffness: keep it when the residual follows it."""
    if not (float(coefs[0]) > 0.3):
        return None
    col = probe.columns[0]
    return {"sigma0": col["sigma0"], "sigma1": col["sigma1"]}


EFFECT = Effect(
    "lugre", __doc__,
    (ParamSpec("sigma0", "N m/rad", "bristle stiffness (presliding spring)", 0.0, 0.0, 1e12),
     ParamSpec("sigma1", "N m s/rad", "bristle micro-damping", 0.0, 0.0, 1e9)),
    "mechanical",
    ("bc",),
    signature=signature,
    guess=guess,
    states=("z",),
    screened=False,
    record="slow reversals with the angle resolved well below bc/sigma0",
)
