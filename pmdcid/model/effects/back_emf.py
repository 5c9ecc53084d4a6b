"""Counter-EMF: the armature equation gains -ke*omega, L di/dt = v - R i - ke omega.

In SI units ke = km. Signature: under load the current falls as the speed rises; steady-state
speed saturates below v*km/(R*bv); current residual correlates with -omega.
"""

from __future__ import annotations

import math

from pmdcid.model.effects.probes import PROBE, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.model.spec import ParamSpec


def probe_size(ctx: ResidualContext) -> float:
    """[V s/rad] a few percent of km (ke = km in SI units)."""
    km = ctx.values.get("km", math.nan)
    if not math.isfinite(km) or km <= 0:
        km = 1.0
    return PROBE * km


EFFECT = Effect(
    "back_emf", __doc__,
    (ParamSpec("ke", "V s/rad", "back-EMF constant", 0.0, 0.0, 1e3),),
    "electrical",
    ("bv", "J"),
    **linear("ke", probe_size),
    record="currents logged at several speeds (steps to different voltages)",
)
