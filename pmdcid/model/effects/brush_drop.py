"""Constant voltage drop vb across the brushes, opposing the driving voltage.

No current flows until |v - ke omega| exceeds vb. Signature: steady current vs voltage is affine
with a dead band; later breakaway at small voltages. A refit that pays for the drop with the
resistance is not a brush drop (:func:`moves_resistance`).
"""

from __future__ import annotations

import math

from pmdcid.model.effects.probes import PROBE, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.model.spec import ParamSpec

#: a brush drop must not move the armature resistance by more than this factor
MAX_R_FACTOR = 1.5


def probe_size(ctx: ResidualContext) -> float:
    """[V] a few percent of the largest voltage."""
    return PROBE * max(ctx.voltage_scale, 1e-6)


def moves_resistance(values: dict[str, float], ctx: ResidualContext,
                     start: dict[str, float]) -> str | None:
    """A brush drop whose refit moved R by more than :data:`MAX_R_FACTOR`."""
    r0, r1 = start.get("R", math.nan), values.get("R", math.nan)
    if r0 > 0 and r1 > 0 and max(r0 / r1, r1 / r0) > MAX_R_FACTOR:
        return (f"implausible: the brush drop moved R from {r0:.4g} to {r1:.4g} ohm (a factor "
                f"{max(r0 / r1, r1 / r0):.2g} > {MAX_R_FACTOR:g}): it pays for itself with the "
                "resistance")
    return None


EFFECT = Effect(
    "brush_drop", __doc__,
    (ParamSpec("vb", "V", "brush voltage drop", 0.0, 0.0, 1e3),),
    "electrical",
    ("R",),
    **linear("vb", probe_size),
    record="currents at several small voltages (blocked-rotor steps at several levels)",
    implausible=moves_resistance,
)
