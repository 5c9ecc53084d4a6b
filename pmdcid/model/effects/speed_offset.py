"""Constant bias on the speed sensor: omega_meas = omega + omega0.

Signature: constant speed residual, visible at rest; angle unaffected. A bias of the size of the
speed is no sensor's offset (:func:`speed_bias_too_large`).
"""

from __future__ import annotations

from pmdcid.model.effects.probes import PROBE, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.model.spec import ParamSpec

#: a speed-sensor bias of this share of the typical speed or more is not a bias
MAX_SPEED_BIAS = 0.5


def probe_size(ctx: ResidualContext) -> float:
    """[rad/s] a few percent of the typical speed."""
    return PROBE * ctx.speed_scale


def speed_bias_too_large(values: dict[str, float], ctx: ResidualContext,
                         start: dict[str, float]) -> str | None:
    """A speed-sensor bias beyond :data:`MAX_SPEED_BIAS` of the typical speed."""
    w0, scale = abs(values.get("omega0", 0.0)), ctx.speed_scale
    if scale > 0 and w0 > MAX_SPEED_BIAS * scale:
        return (f"implausible: a speed-sensor bias of {w0:.3g} rad/s is "
                f"{100 * w0 / scale:.0f} % of the typical speed ({scale:.3g} rad/s): not a "
                "sensor's offset")
    return None


EFFECT = Effect(
    "speed_offset", __doc__,
    (ParamSpec("omega0", "rad/s", "speed sensor bias", 0.0, -1e6, 1e6),),
    "sensor",
    ("bc", "bv"),
    **linear("omega0", probe_size, positive=False),
    requires=("omega",),
    record="rest and motion in both directions (steps of both signs, rest recorded before each)",
    implausible=speed_bias_too_large,
)
