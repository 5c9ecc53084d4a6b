"""The drive applies the command latency seconds late.

A host-paced loop: the USB or serial round trip, a PWM duty taken at the next period. Every
state, the current included, follows the input late (sensor_delay: the outputs read late, the
current on time). Signature: current and speed residuals = -latency x their derivatives after
every input change. Only searched when some log measures the current: on voltage and speed
alone a system started at rest cannot tell an input applied late from outputs read late, and
sensor_delay stands for both.
"""

from __future__ import annotations

from pmdcid.model.effects.probes import delay_probe, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.spec import ParamSpec

EFFECT = Effect(
    "input_delay", __doc__,
    (ParamSpec("latency", "s", "delay between the logged command and the applied input", 0.0,
               0.0, 10.0),),
    "input",
    (),
    **linear("latency", delay_probe),
    requires=("i",),
    record="input edges in logs of their own, with the current logged",
)
