"""On voltage + speed logs (a lumped model), the armature's lag L/R is not written as a delay
where there is none, and a real delay is not taken for the lag (diagnose/lawlag.py, lag.py).

Round trips through ``identify`` (with diagnose) on ``bench/lawlag.py``'s rigs: a bench motor
with back-EMF and an L/R of 2 ms (every parameter moved up to 20 % by the seed), logged as a
5 -> 15 V step while turning and a staircase from rest, speed noise 0.5 rad/s from
``default_rng``. At 100 Hz the L/R is a fifth of a sample: fit-mechanical's steps do not resolve
it and the model comes to diagnose with the lag folded into J. Main at c558e30 added a
``sensor_delay`` of about the L/R in each of the three no-delay cases below and missed the
real delay in both delay cases (fit-mechanical's lag held lag and latency together).
"""

from __future__ import annotations

import pytest

from bench.lawlag import per_volt, scenario
from pmdcid.api import identify
from pmdcid.diagnose.lawlag import lag_holds

DELAYS = ("sensor_delay", "input_delay")
LAG = 2e-3


def test_the_lag_holds_against_a_delay_it_cannot_be_told_from():
    # a delay under two samples must fit decisively better (n log of the ratio beyond 10)
    assert lag_holds(1200, 1095.5, 1094.9, -10.0, delay_samples=0.18)
    assert not lag_holds(1200, 1150.0, 1094.9, -10.0, delay_samples=0.18)
    # from two samples (fit-mechanical's own least latency) it must fit at least as well
    assert not lag_holds(6000, 5987.6, 5986.0, -10.0, delay_samples=3.0)
    assert lag_holds(6000, 5980.0, 5986.0, -10.0, delay_samples=3.0)


@pytest.mark.slow
@pytest.mark.parametrize("rate, truth", [(100.0, "none"), (100.0, "friction_curve")])
def test_no_delay_is_added_where_there_is_none(rate, truth):
    # (and at 1 kHz with a friction curve until session 28: the same seed at 1 kHz with a friction
    # curve and an L/R of 4 ms, asserted more closely, is
    # test_fit_mechanicals_latency_gives_way_to_the_lag_beside_a_friction_curve)
    fit, _, _ = scenario(1, 1e3 * LAG, rate, truth)
    model = identify(fit, diagnose=True, progress=False).model
    assert not [e for e in DELAYS if e in model.effects], model.effects
    if truth == "friction_curve":
        assert "friction_curve" in model.effects, model.effects
    if model.has("tau_e"):  # where a stage wrote the lag, it is the L/R
        assert model.value("tau_e") == pytest.approx(LAG, rel=0.25)


@pytest.mark.slow
@pytest.mark.parametrize("rate", [100.0])
def test_a_real_delay_is_not_taken_for_the_lag(rate):
    # a 2-sample latency beside the 2 ms L/R: fit-mechanical's lag takes both (tau_e about
    # their sum, no delay); diagnose refits the lag with a delay and keeps the delay. On voltage
    # and speed the two trade off, so the split is asserted loosely, their sum closely. (At
    # 1 kHz, a 2 ms latency beside the 2 ms lag, it is split in some seeds only: docs/effects.md.
    # At 500 Hz, where the steps resolve both, the split is asserted closely, J within its
    # errors: test_a_real_delay_beside_the_lag_is_kept_with_it, which this case repeated)
    fit, _, vals = scenario(1, 1e3 * LAG, rate, "sensor_delay")
    model = identify(fit, diagnose=True, progress=False).model
    assert "sensor_delay" in model.effects, model.effects
    lag = model.value("tau_e") if model.has("tau_e") else 0.0
    assert model.value("delay") > 0.5 / rate
    assert model.value("delay") + lag == pytest.approx(vals["delay"] + LAG, rel=0.15)


def _within(model, name: str, true: float, k: float = 2.0) -> bool:
    p = model.parameters[name]
    return abs(p.value - true) <= k * p.stderr


@pytest.mark.slow
@pytest.mark.parametrize("seed, rate", [(2, 500.0), (1, 1000.0)])
def test_a_real_delay_beside_the_lag_is_kept_with_it(seed, rate):
    # a 2-sample latency beside the 2 ms L/R that fit-mechanical's steps resolve both of. Main
    # at cabd12f dropped the delay (fitted at 1.95 and 1.8 samples: under its 2-sample floor)
    # and wrote the lag as their sum (tau_e 5.9 and 3.9 ms), J 23 and 92 se off
    fit, _, vals = scenario(seed, 1e3 * LAG, rate, "sensor_delay")
    model = identify(fit, diagnose=True, progress=False).model
    pv = per_volt(vals)
    assert "sensor_delay" in model.effects, model.effects
    assert model.value("delay") == pytest.approx(vals["delay"], rel=0.2)
    assert model.value("tau_e") == pytest.approx(LAG, rel=0.2)
    assert _within(model, "J", pv["J"]), (model.parameters["J"], pv["J"])


@pytest.mark.slow
def test_fit_mechanicals_latency_gives_way_to_the_lag_beside_a_friction_curve():
    # no delay, L/R 4 ms at 1 kHz, a friction curve the steps' model lacks: fit-mechanical's
    # steps keep a 4.3 ms latency; diagnose's final fit settled the dead zone (written as an
    # interval) at 0.63 V with the delay, and held there the lag in the delay's place fitted
    # worse. Main at cabd12f kept a 1.5 ms delay beside a 2.4 ms lag, J 11 se off
    fit, _, vals = scenario(1, 4.0, 1000.0, "friction_curve")
    model = identify(fit, diagnose=True, progress=False).model
    pv = per_volt(vals)
    assert not [e for e in DELAYS if e in model.effects], model.effects
    assert "friction_curve" in model.effects, model.effects
    assert model.value("tau_e") == pytest.approx(4e-3, rel=0.1)
    assert _within(model, "J", pv["J"]), (model.parameters["J"], pv["J"])


@pytest.mark.slow
def test_the_lag_taken_in_a_round_leaves_the_friction_where_the_lag_less_fit_had_it_not():
    """bench/lawlag.py's hobby motor (R 5 ohm, km = ke 0.01, J 2e-6, friction a few % of the
    stall torque, 500 Hz, L/R 2 ms, seed 1, no effect): fit-mechanical leaves the lag
    unresolved, and the round that would add a delay takes the lag in its place. That lag's
    fit stopped where the lag-less fit had the friction (bc' 0.139 for 0.094, the dead zone on
    its staircase, share 0.26: chi-square 65185 on all data, the truth's 6109), and a friction
    curve, a torque offset and a quadratic drag then stood in for the friction, the held-out
    step from rest 0.017 -> 0.031. Refitted from the share valley's dips, nothing is added and
    no held-out run's error rises through diagnose."""
    from bench.lawlag import predict
    from pmdcid.model import Model
    from pmdcid.pipeline import _diagnose
    from pmdcid.pipeline import identify as run_identify

    fit, held, _ = scenario(1, 2.0, 500.0, "none", "hobby")
    res = run_identify(fit, Model(), run_diagnose=False)
    before = res.model.copy()
    _diagnose(res, fit)
    assert list(res.model.effects) == [], res.model.effects
    for lg in held:
        assert predict(res.model, lg) <= 1.05 * predict(before, lg), lg.name


@pytest.mark.slow
def test_a_law_taken_with_the_lag_must_pay_for_itself_beside_it():
    """bench/pervolt_coverage.py's ``lr-encoder`` on a 4096-count encoder, seed 9 (500 Hz, L/R
    2.6 ms under the 3.2 ms its 50 Hz filter shows: the steps keep no lag). diagnose found the
    lag with a quadratic drag worth 1.7 % of the held-out error, then a friction curve and
    Stribeck friction (each 0.5 % of bc; bv' 27 standard errors off) on a motor with none. The
    law beside the lag alone is not decisive: the lag alone is taken, nothing added, and every
    parameter within 3 standard errors."""
    import bench.pervolt_coverage as coverage

    counts = coverage.ENCODER_COUNTS
    coverage.ENCODER_COUNTS = 4096
    try:
        truth, logs = coverage.case_logs("lr-encoder", 9)
    finally:
        coverage.ENCODER_COUNTS = counts
    res = identify(logs, progress=False)
    assert res.diagnose.summary["added"] == [], res.diagnose.summary["added"]
    for k in ("J", "bv", "bc", "dz", "tau_e"):
        assert _within(res.model, k, truth[k], 3.0), (k, res.model.parameters[k], truth[k])
