"""Which parameters can stand in for a candidate on held-out data (candidates.stand_ins)."""

from __future__ import annotations

import numpy as np
import pytest

import pmdcid
from pmdcid.diagnose.candidates import stand_ins
from pmdcid.io import Log
from pmdcid.simulate import neutral_values, simulate_values

CURVE = ["fc1", "fc2", "fc3"]


def test_a_friction_law_already_in_the_model_stands_in_for_a_new_one():
    free = ["dbv", "J", "bv", "bc", *CURVE]
    # one log per direction: an asymmetry of bv is the curve's shape at a second speed
    # (and J, the lag: a speed law's change reaches held-out data through the inherited state)
    assert stand_ins("viscous_asymmetry", free) == ["J", "bv", *CURVE]
    assert stand_ins("quadratic_drag", ["bq", "J", "bv", "bc", "dbv"]) == ["J", "bv", "dbv"]
    # the base parameters it interacts with, without another effect: as before
    assert stand_ins("quadratic_drag", ["bq", "J", "bv", "bc", "tau_e"]) == ["J", "bv", "tau_e"]


def test_effects_that_share_nothing_do_not_stand_in():
    assert stand_ins("sensor_delay", ["delay", "J", "bv", "bc", *CURVE]) == []
    assert stand_ins("brush_drop", ["vb", "R", "L", "J", "bv", "bc", *CURVE]) == ["R"]
    # a candidate's own parameters are never among them
    assert "bq" not in stand_ins("quadratic_drag", ["bq", "bv", *CURVE])


def test_an_effect_whose_size_is_not_determined_has_no_size():
    """A refit that leaves the effect's parameter without a standard error (its variance not
    positive: NaN, 'not determined') gives a size of 0 standard errors, not infinitely many
    (which passed the size rule)."""
    import math
    from types import SimpleNamespace

    from pmdcid.diagnose.candidates import effect_z
    from pmdcid.fit.results import fitted
    from pmdcid.model import EFFECTS

    eff = EFFECTS["torque_offset"]
    fo = SimpleNamespace(estimates={"tau0": fitted("tau0", 0.01, math.nan, "N m")})
    assert effect_z(eff, fo) == 0.0
    fo = SimpleNamespace(estimates={"tau0": fitted("tau0", 0.01, 0.002, "N m")})
    assert effect_z(eff, fo) == pytest.approx(5.0)


MOTOR = {**neutral_values(), "R": 1.8, "L": 1e-3, "km": 0.017, "ke": 0.017, "J": 1e-4,
         "bv": 2e-6, "bc": 1.6e-3, "dz": 1e-3}
SAG = 0.5  # ohm: the supply sags with the current
COUNT = 2 * np.pi / 256  # rad: one encoder count


def _firmware_run(levels: np.ndarray, rng) -> dict[str, np.ndarray]:
    """A 1 kHz loop that measures the terminal voltage: over each sample the drive applies the
    command less the supply's sag at the current then, and the row written at the sample's end
    holds that voltage (0.3 V of noise), the current (20 mA) and a 256-count encoder's speed."""
    n = len(levels)
    x = np.zeros(3)
    applied, i, theta = np.zeros(n), np.zeros(n), np.zeros(n)
    tt = np.array([0.0, 1e-3])
    for k in range(n - 1):
        i[k], theta[k] = x[0], x[2]
        applied[k] = levels[k] - SAG * x[0]
        s = simulate_values(tt, np.full(2, applied[k]), MOTOR, x0=tuple(x))
        x = np.array([s.i[1], s.omega[1], s.theta[1]])
    i[-1], theta[-1] = x[0], x[2]
    w = np.concatenate([[0.0], np.diff(np.floor(theta / COUNT))]) * COUNT / 1e-3
    v = np.concatenate([[0.0], applied[:-1]])
    return {"v": v + rng.normal(0, 0.3, n), "i": i + rng.normal(0, 0.02, n), "omega": w}


def _step_logs(seed: int) -> list[Log]:
    rng = np.random.default_rng(seed)
    t = np.arange(7000) / 1000.0
    return [Log(f"step{a}_{b}.csv", t,
                _firmware_run(np.where((t >= 1) & (t < 4), b, a).astype(float), rng))
            for a, b in ((0, 6), (3, 9), (0, 12))]


@pytest.mark.slow
def test_an_effect_that_raises_the_speed_over_the_starting_model_is_not_added():
    """bench/newrigs.py freerun-vmeas seed 20: free-running steps whose logged voltage is
    measured (0.3 V of noise, the voltage of the sample before). diagnose's base refit freed R
    and L with the current: L went from fit-electrical's 6.5e-5 H to 3e-13 H and the speed's
    error rose; an effect that took back part of it passed against that refit, and a
    `voltage_saturation` the motor does not have was added (seeds 0 and 1) and the speed's error
    rose 6-16 % on every log (seed 0). Judged against the model diagnose started from as well
    (`candidates.held_speed_rise`): nothing added, the speed's error as identify left it. (Seed
    1 still adds that `voltage_saturation`, fitted on the current's timing; there the speed's
    error stays within 1 %: the rule is the speed's, not the effect's name.)"""
    logs = _step_logs(0)
    start = pmdcid.identify(logs, diagnose=False).model
    res = pmdcid.diagnose(logs, start)
    assert res.model.effects == start.effects
    for name in ("R", "L"):
        assert res.model.value(name) == start.value(name)
    for before, after in zip(res.before, res.after, strict=True):
        assert after["omega"] <= 1.01 * before["omega"]
