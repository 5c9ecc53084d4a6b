"""identify/plausibility.py: the stuck-rotor rule never refuses a real slow motor.

The rule (:func:`stuck_issue`) refuses a model whose Coulomb friction or dead zone is at or
beyond the largest torque a log's input applies while that log's rotor visibly turns from rest.
A real motor that turns has its friction below its drive, so the rule sits at the physics'
boundary: a slow geared motor whose friction is just below its stall torque, logged with a speed
noise half its speed, or a low speed logged in whole rpm, is never refused by its true model.
"""

from __future__ import annotations

import numpy as np
import pytest

from pmdcid.identify.plausibility import stuck_issue, turns_from_rest
from pmdcid.io import Log
from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.synth import triangle, truth_model

RPM = 60 / (2 * np.pi)
#: a geared motor seen at its output: friction near its stall torque km |v| / R (0.0953 N m at
#: the 4.5 V peak), so the output turns slowly (about 1 rad/s at most)
GEARED = {"R": 2.37, "L": 0.0178, "km": 0.0502, "J": 0.05, "bv": 0.05, "bc": 0.04,
          "dz": 0.045}
STALL = GEARED["km"] * 4.5 / GEARED["R"]


def _geared_log(rng, noise: float) -> Log:
    t = np.arange(40000) * 1e-3
    u = triangle(t, 4.5, 20.0)
    sim = simulate_values(t, u, {**neutral_values(), **GEARED})
    om = sim.omega + rng.normal(0.0, noise, t.size)
    return Log.from_arrays(t, v=u, omega=om, name="geared.csv")


def test_slow_geared_motor_is_not_refused_by_its_true_model(rng):
    log = _geared_log(rng, noise=0.01)
    assert turns_from_rest(log)  # the rule applies: the output visibly turns from rest
    assert stuck_issue(truth_model(GEARED), [log]) is None
    close = truth_model({**GEARED, "bc": 0.97 * STALL, "dz": 0.98 * STALL})
    assert stuck_issue(close, [log]) is None  # no margin below the drive that a fit could cross
    beyond = truth_model({**GEARED, "bc": 1.02 * STALL})
    assert "geared.csv" in stuck_issue(beyond, [log])


@pytest.mark.parametrize("noise", [0.5, 0.05])
def test_noisy_slow_motor_is_not_refused(rng, noise):
    """1 rad/s at most, a speed noise of 0.5 rad/s (or 0.05): the true model and one whose
    friction is just under the stall torque pass."""
    log = _geared_log(rng, noise)
    for vals in (GEARED, {**GEARED, "bc": 0.97 * STALL, "dz": 0.98 * STALL}):
        assert stuck_issue(truth_model(vals), [log]) is None


def test_low_speed_logged_in_whole_rpm_is_not_refused(rng):
    """The paper's motor at 0.6 V (2.3 rpm at most), its speed logged in whole rpm and mapped
    to rad/s: the quantised speed does not make the rule refuse the true model."""
    vals = {"R": 2.3724, "L": 17.7933e-3, "km": 50.2e-3, "J": 3.10442e-3, "bv": 0.0314,
            "bc": 0.005, "dz": 6.35e-3}
    t = np.arange(40000) * 1e-3
    u = triangle(t, 0.6, 20.0)
    sim = simulate_values(t, u, {**neutral_values(), **vals})
    om = np.round((sim.omega + rng.normal(0.0, 0.01, t.size)) * RPM) / RPM
    log = Log.from_arrays(t, v=u, omega=om, name="rpm.csv")
    assert stuck_issue(truth_model(vals), [log]) is None
    stall = vals["km"] * 0.6 / vals["R"]
    assert stuck_issue(truth_model({**vals, "bc": 0.97 * stall}), [log]) is None


def test_a_mechanical_time_constant_shorter_than_any_motor_names_the_time_unit(rng):
    """The paper's motor logged at 1 kHz, its t (seconds) mapped as ms: every time constant
    comes out 1000 x short and many samples long. The true model at the true clock passes; the
    same motor scaled to that clock (J / 1000) is refused naming t; a J under a sample period
    (not resolved: a slow log, not a unit) is not."""
    from pmdcid.errors import LogError
    from pmdcid.identify.plausibility import gate_result

    vals = {"R": 2.3724, "L": 17.7933e-3, "km": 50.2e-3, "J": 3.10442e-3, "bv": 0.0314,
            "bc": 0.005, "dz": 6.35e-3}
    t = np.arange(3000) * 1e-3
    u = np.where(t > 0.5, 2.0, 0.0)
    om = simulate_values(t, u, {**neutral_values(), **vals}).omega
    om = om + rng.normal(0, 0.05, t.size)
    gate_result(truth_model(vals), [Log.from_arrays(t, v=u, omega=om, name="s.csv")])
    fast = Log.from_arrays(t * 1e-3, v=u, omega=om, name="ms.csv")
    with pytest.raises(LogError, match=r"ms\.csv: the fitted mechanical time constant .* "
                                       "shorter than any motor.s.*t is scaled too small"):
        gate_result(truth_model({**vals, "J": vals["J"] * 1e-3, "L": vals["L"] * 1e-3}), [fast])
    slow = Log.from_arrays(t * 20, v=u, omega=om, name="slow.csv")  # 20 ms samples
    gate_result(truth_model({**vals, "J": 1e-6}), [slow])


@pytest.mark.parametrize("levels", [(6.0,), (3.0, 6.0, 9.0)])
def test_a_voltage_in_millivolts_is_refused_where_a_drivers_drop_is_not(rng, levels):
    """The paper's motor stepped to one or three levels, its current and speed logged: v in mV
    (x 1000) is refused by the back-EMF balance; a driver that drops 2 V of each command
    (logged as commanded) and the true volts pass."""
    from pmdcid.errors import LogError
    from pmdcid.identify.plausibility import gate

    vals = {"R": 2.3724, "L": 17.7933e-3, "km": 50.2e-3, "J": 3.10442e-3, "bv": 0.0314,
            "bc": 0.005, "dz": 6.35e-3}
    t = np.arange(3000 * len(levels)) * 1e-3
    u = np.zeros_like(t)
    for k, lv in enumerate(levels):
        u[(t >= 3.0 * k + 0.2)] = lv

    def log(cmd, applied, name):
        sim = simulate_values(t, applied, {**neutral_values(), **vals})
        return Log.from_arrays(t, v=cmd, i=sim.i + rng.normal(0, 0.005, t.size),
                               omega=sim.omega + rng.normal(0, 0.05, t.size), name=name)

    km, R = vals["km"], vals["R"]
    gate([log(u, u, "volts.csv")], km=km, R=R)
    gate([log(u, np.where(u > 0, u - 2.0, 0.0), "drop.csv")], km=km, R=R)
    with pytest.raises(LogError, match=r"mv\.csv: the back-EMF v - R\*i .* km\*omega.*in mV"):
        gate([log(1000 * u, u, "mv.csv")], km=km, R=R)
