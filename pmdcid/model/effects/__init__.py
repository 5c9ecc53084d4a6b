"""The effect catalogue: named, composable physical effects the paper's model lacks.

One module per effect holds all of it but the kernel term: its :class:`Effect` record
(``EFFECT``: parameters, where it acts, physics and residual signature as the module's
docstring, what to record to test it) and what diagnose needs to search for it: its probes and
starting guess, tighter refit bounds (``limits``) and a physical bound on its refitted size
(``implausible``). The kernel term lives in :mod:`pmdcid.simulate.terms` (or
:mod:`pmdcid.simulate.sensors`), where numba compiles it from the flat parameter vector.
Shared pieces: :mod:`.registry` (the record and the queries), :mod:`.probes` (probe sizes, the
probe of a near-linear parameter), :mod:`.friction` (the logged speeds and the total friction
over them), :mod:`.torque_limit` (the model reader's rule: effect torques against the motor's).

Adding an effect: a module here, its line in :data:`CATALOGUE`, and its term in the kernel. See
docs/effects.md.
"""

from __future__ import annotations

from pmdcid.model.effects import (
    back_emf,
    brush_drop,
    cogging,
    friction_curve,
    input_delay,
    lugre,
    quadratic_drag,
    sensor_delay,
    speed_offset,
    stribeck,
    torque_offset,
    viscous_asymmetry,
    voltage_saturation,
)
from pmdcid.model.effects.registry import (
    EFFECTS,
    Effect,
    bounds_of,
    effect_param_specs,
    param_spec,
    range_only,
    register,
    stderr_words,
    unit_of,
    within_range,
)

#: the catalogue in its registration order, which is diagnose's search order (its screen, its
#: ties and its summaries follow it) and the order ``--effect`` lists them in
CATALOGUE = (back_emf, stribeck, quadratic_drag, torque_offset, cogging, sensor_delay,
             speed_offset, voltage_saturation, brush_drop, viscous_asymmetry, friction_curve,
             input_delay, lugre)

for _module in CATALOGUE:
    register(_module.EFFECT)

__all__ = ["CATALOGUE", "EFFECTS", "Effect", "bounds_of", "effect_param_specs", "param_spec",
           "range_only", "stderr_words", "unit_of", "within_range"]
