"""A constant latency on voltage-and-speed step logs (lumped model, no electrical lag).

Round trip: the lumped paper motor's free-speed steps (1 kHz, speed noise from
``default_rng(seed)``), the speed read 3.5 ms late; fit-mechanical per volt must keep the latency
as ``sensor_delay`` within one sample, and the same steps without latency must not get one. The
paper's next stage then fits the triangle with the latency held: J, bv, bc within 2 %.
"""

from __future__ import annotations

import numpy as np
import pytest
from ident_util import LUMPED, as_log

from pmdcid.identify.latency import MIN_SAMPLES, step_latency
from pmdcid.model import Model
from pmdcid.model.lumped import mark_lumped
from pmdcid.pipeline import _mechanical, _nonlinear
from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.synth import step, triangle

VALS = {**neutral_values(), **LUMPED, "R": 1.0, "L": 1.0, "km": 1.0}
DT = 1e-3


def _late(t, u, delay, rng, noise=0.05):
    om = simulate_values(t, u, VALS, torque_driven=True).omega
    om = np.interp(t - delay, t, om, left=0.0)
    return {"v": u, "omega": om + rng.normal(0.0, noise, t.size)}


def _steps(delay, seed):
    rng = np.random.default_rng(seed)
    t = np.arange(3000) * DT
    return [as_log(f"step_{a}V", t, _late(t, step(t, a, 0.5), delay, rng))
            for a in (1.0, 1.5, 2.0, 2.5)]


def _lumped():
    m = Model()
    mark_lumped(m)
    return m


@pytest.mark.parametrize("delay", [0.0035, 0.012])
def test_steps_latency_is_kept_as_sensor_delay(delay):
    m = _lumped()
    _mechanical(_steps(delay, seed=11), m).apply(m)
    assert "sensor_delay" in m.effects
    assert abs(m.parameters["delay"].value - delay) <= DT


def test_no_latency_no_sensor_delay():
    m = _lumped()
    res = _mechanical(_steps(0.0, seed=12), m)
    res.apply(m)
    assert "sensor_delay" not in m.effects and "delay" not in res.estimates
    assert step_latency(_steps(0.0, seed=13), m) is None  # under MIN_SAMPLES samples
    assert MIN_SAMPLES >= 1


def test_paper_sequence_with_latency_recovers_the_lumped_motor():
    m = _lumped()
    _mechanical(_steps(0.0035, seed=14), m).apply(m)
    rng = np.random.default_rng(15)
    t = np.arange(40000) * DT
    tri = as_log("triangle", t, _late(t, triangle(t, 3.0, 20.0), 0.0035, rng))
    _nonlinear(True)([tri], m).apply(m)
    for k in ("J", "bv", "bc"):
        assert m.parameters[k].value == pytest.approx(LUMPED[k], rel=0.02), k
