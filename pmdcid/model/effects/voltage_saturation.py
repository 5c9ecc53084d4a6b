"""The drive clips the applied voltage to +-vmax.

Signature: speed residual only where |v| is large, flat-topped speed peaks.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import Probe, ResidualContext
from pmdcid.model.spec import ParamSpec

#: voltage limits tried (the limit enters non-linearly), as fractions of the largest voltage
SATURATION_FRACTIONS = (0.95, 0.85, 0.7, 0.5)


def signature(ctx: ResidualContext) -> list[Probe]:
    if ctx.voltage_scale <= 0:
        return []
    return [Probe([{"vmax": f * ctx.voltage_scale}], f"vmax={f * ctx.voltage_scale:.3g}")
            for f in SATURATION_FRACTIONS]


def guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """The probe is the full effect at that limit: keep it when the residual follows it."""
    if not (float(coefs[0]) > 0.3):
        return None
    return {"vmax": probe.columns[0]["vmax"]}


EFFECT = Effect(
    "voltage_saturation", __doc__,
    (ParamSpec("vmax", "V", "drive voltage limit", math.inf, 1e-6, math.inf),),
    "input",
    (),
    signature=signature,
    guess=guess,
    record="inputs near and below the drive's limit in separate logs",
)
