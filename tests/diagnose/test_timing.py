"""A lag that changes along a log (host-paced time stamps drifting against the command).

Round trips: a course-lab motor simulated on a pulse staircase from known parameters, its speed
read through a lag d(t) and white noise from ``default_rng(seed)``. A constant lag (what
input_delay / sensor_delay model) must not be reported and must be placed within two samples; a
lag growing by eps * t (a sample clock 0.2 % slower than the host's) or a sawtooth (a buffer
flushed half-way) must be reported, with its trend within 30 %. diagnose's warning names the log.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from ident_util import as_log

from pmdcid.diagnose.timing import lag_profile, timing_warning
from pmdcid.io.derive import noise_std
from pmdcid.simulate import neutral_values, simulate_values

#: a course-lab gear motor on a 12 V PWM drive (SI), as in test_drive_effects
COURSE = {"R": 3.4, "L": 2.85e-3, "km": 0.048, "ke": 0.048, "J": 1.0e-5, "bv": 3.0e-5,
          "bc": 3.0e-3, "dz": 0.0}
DT = 1e-3
#: speed noise std [rad/s]
NOISE = 0.4


def _staircase(t: np.ndarray) -> np.ndarray:
    """Pulses 3, 5, 7, ... V, each 1.5 s on and 1 s off [V]."""
    k = (t // 2.5).astype(int)
    on = (t % 2.5) >= 1.0
    return np.where(on, 3.0 + 2.0 * (k % 5), 0.0)


def _rig(lag, seed: int, vals=None):
    """(t, u, simulated speed of the true model, measured speed read through ``lag(t)`` [s])."""
    t = np.arange(int(25.0 / DT)) * DT
    u = _staircase(t)
    true = simulate_values(t, u, {**neutral_values(), **COURSE}).omega
    rng = np.random.default_rng(seed)
    meas = np.interp(t - lag(t), t, true, left=0.0) + rng.normal(0.0, NOISE, t.size)
    model = true if vals is None else simulate_values(t, u, {**neutral_values(), **vals}).omega
    return t, u, model, meas


def test_a_constant_lag_is_placed_and_not_reported():
    t, _, sim, meas = _rig(lambda t: 0.040 + 0 * t, seed=1)
    p = lag_profile(t, sim, meas, noise_std(meas))
    assert p is not None and len(p.lags) >= 5
    assert abs(p.common - 0.040) <= 2 * DT
    assert not p.varies, (p.gain, p.spread)


def test_no_lag_and_a_wrong_inertia_are_not_reported():
    # a model 30 % off in J and bc misses the transients, but by the same amount at each pulse
    wrong = {**COURSE, "J": 1.3 * COURSE["J"], "bc": 0.7 * COURSE["bc"]}
    for vals in (None, wrong):
        t, _, sim, meas = _rig(lambda t: 0 * t, seed=2, vals=vals)
        p = lag_profile(t, sim, meas, noise_std(meas))
        assert not p.varies, (vals, p.gain, p.spread)


def test_a_drifting_lag_is_reported_with_its_trend():
    eps = 2e-3  # the speed's clock 0.2 % slower than the command's
    t, _, sim, meas = _rig(lambda t: 0.005 + eps * t, seed=3)
    p = lag_profile(t, sim, meas, noise_std(meas))
    assert p.varies, (p.gain, p.spread)
    assert abs(p.slope - eps) <= 0.3 * eps


def test_a_sawtooth_lag_is_reported():
    t, _, sim, meas = _rig(lambda t: 0.005 + 4e-3 * (t % 12.5), seed=4)
    p = lag_profile(t, sim, meas, noise_std(meas))
    assert p.varies, (p.gain, p.spread)


def test_diagnose_warning_names_the_drifting_log_only():
    sims, logs = [], []
    for name, lag, seed in (("steady", lambda t: 0.02 + 0 * t, 5),
                            ("drifting", lambda t: 0.005 + 3e-3 * t, 6)):
        t, u, sim, meas = _rig(lag, seed)
        logs.append(as_log(name, t, {"v": u, "omega": meas}))
        sims.append(SimpleNamespace(omega=sim))
    problem = SimpleNamespace(logs=logs, blocked=[False, False])
    line = timing_warning(problem, sims)
    assert line is not None and "drifting" in line and "steady" not in line
    assert timing_warning(SimpleNamespace(logs=logs[:1], blocked=[False]), sims[:1]) is None


def test_two_windows_off_either_way_are_not_a_drift():
    # one pulse seen 6 ms late and the next 6 ms early: no clock drifts like that
    def lag(t):
        return 0.02 + np.where((t >= 7.5) & (t < 10.0), 0.006, 0.0) \
            - np.where((t >= 10.0) & (t < 12.5), 0.006, 0.0)

    t, _, sim, meas = _rig(lag, seed=7)
    p = lag_profile(t, sim, meas, noise_std(meas))
    assert p.spread >= 0.005  # the windows see it (the worst one of the two is left out)
    assert not p.varies, (p.gain, p.spread, p.slope)
