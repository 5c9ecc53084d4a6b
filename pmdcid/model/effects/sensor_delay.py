"""Speed and angle measured late by delay seconds (filtering, communication).

Signature: residual is the derivative of the signal times -delay; cross-correlation peak at a
lag > 0. A refit beyond a few samples and a share of the mechanical time constant stands in for
a slower response the model lacks (:func:`delay_too_long`).
"""

from __future__ import annotations

import math

from pmdcid.model.effects.probes import delay_probe, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.model.spec import ParamSpec

#: a logged speed or angle is read late by a few sample periods (an encoder's counting window,
#: a filter) ...
MAX_DELAY_SAMPLES = 5
#: ... or by a transport latency that stays a small share of the mechanical time constant: a
#: delay of the order of the time constant competes with the inertia for the same lag
MAX_DELAY_SHARE = 0.25


def mechanical_time_constant(values: dict[str, float]) -> float:
    """J over the total viscous damping [s]: J/(bv + km ke/R) (per volt, bv already holds ke);
    NaN when J or the damping is unknown."""
    j, bv = values.get("J", math.nan), values.get("bv", math.nan)
    km, ke, r = values.get("km", 0.0), values.get("ke", 0.0), values.get("R", math.nan)
    damping = bv + (km * ke / r if r > 0 and km > 0 and ke > 0 else 0.0)
    return j / damping if j > 0 and damping > 0 else math.nan


def sensor_lag_limit(values: dict[str, float], dt: float) -> float:
    """The longest lag [s] a speed or angle sensor adds to what it logs, sampled every ``dt``
    [s]: :data:`MAX_DELAY_SAMPLES` sample periods or :data:`MAX_DELAY_SHARE` of the mechanical
    time constant, whichever is longer. It bounds a sensor delay and the time constant of a
    sensor's own filter (the colour of its noise: :func:`pmdcid.fit.simfit.ar_whitener`); a
    slower lag is the motor's response, not the sensor's."""
    tau = mechanical_time_constant(values)
    return max(MAX_DELAY_SAMPLES * dt, MAX_DELAY_SHARE * tau if math.isfinite(tau) else 0.0)


def delay_too_long(values: dict[str, float], ctx: ResidualContext,
                   start: dict[str, float]) -> str | None:
    """A sensor delay beyond :func:`sensor_lag_limit`."""
    delay, dt = values.get("delay", 0.0), ctx.dt
    tau = mechanical_time_constant(values)
    if dt > 0 and delay > sensor_lag_limit(values, dt):
        return (f"implausible: a sensor delay of {delay:.3g} s ({delay / dt:.0f} samples, "
                f"{delay / tau:.2g} of the mechanical time constant {tau:.3g} s) stands in for "
                f"a slower response the model lacks; a sensor reads at most a few samples or "
                f"{MAX_DELAY_SHARE:g} of the time constant late")
    return None


EFFECT = Effect(
    "sensor_delay", __doc__,
    (ParamSpec("delay", "s", "measurement delay of speed and angle", 0.0, 0.0, 10.0),),
    "sensor",
    (),
    **linear("delay", delay_probe),
    record="input edges or reversals in logs of their own (steps at other levels, a square wave)",
    implausible=delay_too_long,
)
