"""Physical bounds on the size of an effect, beyond its parameters' declared bounds.

A refit may move an effect to a size no motor or sensor has, because there it stands in for
something else the model lacks: a "sensor delay" of ten samples standing for a slower mechanical
response, a "brush drop" that pays for it by cutting R by a factor, a "speed-sensor bias" of the
size of the speed. Each function answers why a size is not physical for these logs (a reason in
words) or None. ``values``: the refit's parameters; ``ctx``: the residual context
(:class:`pmdcid.model.residual.ResidualContext`: scales and the shortest sample period
``dt`` [s]); ``start``: the parameter values before diagnose.
"""

from __future__ import annotations

import math

#: a logged speed or angle is read late by a few sample periods (an encoder's counting window,
#: a filter) ...
MAX_DELAY_SAMPLES = 5
#: ... or by a transport latency that stays a small share of the mechanical time constant: a
#: delay of the order of the time constant competes with the inertia for the same lag
MAX_DELAY_SHARE = 0.25
#: a speed-sensor bias of this share of the typical speed or more is not a bias
MAX_SPEED_BIAS = 0.5
#: a brush drop must not move the armature resistance by more than this factor
MAX_R_FACTOR = 1.5


def mechanical_time_constant(values: dict[str, float]) -> float:
    """J over the total viscous damping [s]: J/(bv + km ke/R) (per volt, bv already holds ke);
    NaN when J or the damping is unknown."""
    j, bv = values.get("J", math.nan), values.get("bv", math.nan)
    km, ke, r = values.get("km", 0.0), values.get("ke", 0.0), values.get("R", math.nan)
    damping = bv + (km * ke / r if r > 0 and km > 0 and ke > 0 else 0.0)
    return j / damping if j > 0 and damping > 0 else math.nan


def delay_too_long(values: dict[str, float], ctx, start: dict[str, float]) -> str | None:
    """A sensor delay beyond both :data:`MAX_DELAY_SAMPLES` sample periods and
    :data:`MAX_DELAY_SHARE` of the mechanical time constant."""
    delay, dt = values.get("delay", 0.0), ctx.dt
    tau = mechanical_time_constant(values)
    limit = max(MAX_DELAY_SAMPLES * dt, MAX_DELAY_SHARE * tau if math.isfinite(tau) else 0.0)
    if dt > 0 and delay > limit:
        return (f"implausible: a sensor delay of {delay:.3g} s ({delay / dt:.0f} samples, "
                f"{delay / tau:.2g} of the mechanical time constant {tau:.3g} s) stands in for "
                f"a slower response the model lacks; a sensor reads at most a few samples or "
                f"{MAX_DELAY_SHARE:g} of the time constant late")
    return None


def speed_bias_too_large(values: dict[str, float], ctx, start: dict[str, float]) -> str | None:
    """A speed-sensor bias beyond :data:`MAX_SPEED_BIAS` of the typical speed."""
    w0, scale = abs(values.get("omega0", 0.0)), ctx.speed_scale
    if scale > 0 and w0 > MAX_SPEED_BIAS * scale:
        return (f"implausible: a speed-sensor bias of {w0:.3g} rad/s is "
                f"{100 * w0 / scale:.0f} % of the typical speed ({scale:.3g} rad/s): not a "
                "sensor's offset")
    return None


def moves_resistance(values: dict[str, float], ctx, start: dict[str, float]) -> str | None:
    """A brush drop whose refit moved R by more than :data:`MAX_R_FACTOR`."""
    r0, r1 = start.get("R", math.nan), values.get("R", math.nan)
    if r0 > 0 and r1 > 0 and max(r0 / r1, r1 / r0) > MAX_R_FACTOR:
        return (f"implausible: the brush drop moved R from {r0:.4g} to {r1:.4g} ohm (a factor "
                f"{max(r0 / r1, r1 / r0):.2g} > {MAX_R_FACTOR:g}): it pays for itself with the "
                "resistance")
    return None


__all__ = ["MAX_DELAY_SAMPLES", "MAX_DELAY_SHARE", "MAX_R_FACTOR", "MAX_SPEED_BIAS",
           "delay_too_long", "mechanical_time_constant", "moves_resistance",
           "speed_bias_too_large"]
