"""Effect torques checked against the motor they belong to, not only against their bounds.

A parameter's bounds (:mod:`pmdcid.model.spec`) are wide: they must hold for a watch motor and a
crane. Within them a value can still be absurd *for this model*: a cogging amplitude of 1e6 N m
on a motor whose stall torque is 0.02 N m per volt makes a simulation run away (5e6 rad/s) and
write that as data. The rule: every effect parameter that is a torque (unit ``N m``; per volt in
a lumped model) lies within :data:`TORQUE_MARGIN` times the largest torque the motor makes
(:func:`motor_torque`); otherwise the model is refused with one line naming the parameter.
The model reader's rule, for any model; a refit's size against the logs it was fitted to is
each effect's own ``implausible`` (:class:`~pmdcid.model.effects.registry.Effect`).
"""

from __future__ import annotations

import math

from pmdcid.errors import ModelError
from pmdcid.model.effects.registry import EFFECTS
from pmdcid.model.spec import BASE_PARAMS

#: an effect's torque may be at most this many times the largest torque the motor makes
TORQUE_MARGIN = 10.0
#: the largest drive voltage assumed when the model states none (voltage_saturation's vmax) [V]
V_PLAUSIBLE = 1000.0
#: base parameters that are themselves torques (the scale of a torque-driven model)
BASE_TORQUES = ("bc", "dz")


def motor_torque(values: dict[str, float], lumped: bool = False) -> float | None:
    """The largest torque the motor can make [N m] (per volt: [V] in a lumped model): the stall
    torque km V / R at the drive's limit (vmax, else :data:`V_PLAUSIBLE`); for a torque-driven
    model the largest base friction torque; None when the model says nothing about it."""
    v = values.get("vmax", math.inf)
    v = v if math.isfinite(v) and v > 0 else V_PLAUSIBLE
    if lumped:
        return v
    if values.get("km", 0) > 0 and values.get("R", 0) > 0:
        return values["km"] * v / values["R"]
    base = [abs(values[n]) for n in BASE_TORQUES if n in values]
    return max(base) * 1e3 if base and max(base) > 0 else None


def check_plausible(values: dict[str, float], path=None, lumped: bool = False) -> None:
    """Refuse an effect torque beyond :data:`TORQUE_MARGIN` x :func:`motor_torque` (one line)."""
    scale = motor_torque(values, lumped)
    if scale is None:
        return
    limit = TORQUE_MARGIN * scale
    for eff in EFFECTS.values():
        for spec in eff.params:
            v = values.get(spec.name)
            if v is None or spec.name in BASE_PARAMS or spec.unit != "N m" or abs(v) <= limit:
                continue
            unit = "V (per volt)" if lumped else "N m"
            raise ModelError(
                f"parameter '{spec.name}' ({eff.name}) = {v:g} {unit} is implausible for this "
                f"motor: more than {TORQUE_MARGIN:g} x its torque scale {scale:.3g} {unit} "
                "(stall torque km V/R); check its unit, or remove it and rerun diagnose", path)


__all__ = ["TORQUE_MARGIN", "check_plausible", "motor_torque"]
