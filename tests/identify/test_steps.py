"""Finding steps in a *measured* (noisy) voltage: a drive that logs the armature voltage through a
divider and an ADC, or the PWM average, instead of the command (issue #24, item 7). The steps
are found against the log's own noise, the levels are plateau means, a rich input stays rich."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdcid.errors import FitError
from pmdcid.identify.steps import find_steps, held_levels, held_steps

#: the lead's three step logs: 4 s, the level changing at 1 s and 2.5 s (0->6->0, 3->9->3, 0->12->0)
LEVELS = ((0.0, 6.0), (3.0, 9.0), (0.0, 12.0))


def _steps(rate: float, low: float, high: float) -> tuple[np.ndarray, np.ndarray]:
    t = np.arange(0.0, 4.0, 1.0 / rate)
    return t, np.where((t >= 1.0) & (t < 2.5), high, low)


@pytest.mark.parametrize("rate", [1000.0, 500.0, 100.0])
@pytest.mark.parametrize("sigma_v", [0.3, 1.0, 1.5])
def test_steps_in_a_noisy_measured_voltage_are_all_found(rate, sigma_v):
    """0.3-1.5 V of white noise on the logged voltage (a 6 V step is 4 noise std): both changes
    of every log found within one sample, the log held at levels, each level its plateau's mean
    (within 4 standard errors sigma/sqrt(n) of the truth). Measured on 20 seeds of each case
    (540 logs): the onset exact in 1070 of 1080 steps, one sample off in 10; the levels'
    z-scores mean 0.00, std 1.00. Before: a change had to be 8 sigma between two samples, so the 6 V
    steps at 1 V of noise were missed and the logs called rich."""
    rng = np.random.default_rng(int(rate) + int(10 * sigma_v))
    for low, high in LEVELS:
        t, v = _steps(rate, low, high)
        vm = v + rng.normal(0.0, sigma_v, len(t))
        found = find_steps(t, vm)
        assert [s.t0 for s in found] == pytest.approx([1.0, 2.5], abs=1.5 / rate)
        assert len(held_steps(t, vm)) == 2
        for s, level in zip(found, (high, low), strict=True):
            n = (s.end if s.end is not None else len(t)) - s.onset
            assert abs(s.after - level) < 4 * sigma_v / math.sqrt(n)


@pytest.mark.parametrize("ripple_hz", [137.0, 3.0])
@pytest.mark.parametrize("sigma_v", [0.0, 0.3])
def test_pwm_duty_times_a_rippling_supply_is_held_at_levels(ripple_hz, sigma_v):
    """v = duty x a supply rippling 5 % (fast: 137 Hz at 1 kHz; slow: 3 Hz, under 5 periods per
    plateau), with or without noise: still two steps, each level the duty's within 2 %."""
    rng = np.random.default_rng(7)
    for low, high in LEVELS:
        t, duty = _steps(1000.0, low, high)
        v = duty * (1 + 0.05 * np.sin(2 * np.pi * ripple_hz * t + 1.0))
        v = v + rng.normal(0.0, sigma_v, len(t))
        steps = held_steps(t, v)
        assert [s.t0 for s in steps] == pytest.approx([1.0, 2.5], abs=2e-3)
        for s, level in zip(steps, (high, low), strict=True):
            assert s.after == pytest.approx(level, abs=0.02 * high)


def _rich(t: np.ndarray) -> dict[str, np.ndarray]:
    T = float(t[-1])
    phase = 2 * np.pi * (0.5 * t + 0.5 * (20.0 - 0.5) / T * t ** 2)
    return {"chirp": 6 * np.sin(phase), "ramp": 12 * t / T, "sine": 6 * np.sin(2 * np.pi * t),
            "triangle": 12 * (1 - np.abs(2 * ((2 * t / T) % 1) - 1))}


@pytest.mark.parametrize("rate", [1000.0, 100.0])
@pytest.mark.parametrize("sigma_v", [0.0, 0.3, 1.0, 1.5])
def test_rich_inputs_stay_rich_however_noisy(rate, sigma_v):
    """A chirp, a ramp, a sine and a triangle are held at no levels, clean or noisy: a change
    seen only between averages must be a jump between two flat plateaus, not a wave cut in
    two."""
    rng = np.random.default_rng(int(rate) + int(10 * sigma_v))
    t = np.arange(0.0, 4.0, 1.0 / rate)
    for name, u in _rich(t).items():
        assert held_steps(t, u + rng.normal(0.0, sigma_v, len(t))) == [], name


def test_a_noisy_ramp_holds_no_step():
    with pytest.raises(FitError, match="no step found"):
        t = np.arange(4000) / 1000.0
        find_steps(t, 3 * t + np.random.default_rng(3).normal(0.0, 1.0, len(t)))


def test_held_levels_average_the_plateaus_of_a_noisy_input_only():
    """A noisy input held at levels comes back as its plateaus' means; a clean one (nothing to
    average) and a rich one give None."""
    rng = np.random.default_rng(11)
    t, v = _steps(1000.0, 3.0, 9.0)
    assert held_levels(t, v) is None
    vm = v + rng.normal(0.0, 1.0, len(t))
    held = held_levels(t, vm)
    assert held is not None and len(np.unique(held.u)) == 3
    h = held.u
    assert h[1200] == pytest.approx(float(np.mean(vm[1000:2500])), abs=0.01)
    assert h[100] == pytest.approx(float(np.mean(vm[:1000])), abs=0.01)
    assert np.max(np.abs(h - v)) < 0.15
    assert [(a, e) for a, e, _ in held.plateaus] == [(0, 1000), (1000, 2500), (2500, 4000)]
    assert held.plateaus[1][2] == pytest.approx(1.0 / math.sqrt(1500), rel=0.15)
    assert held_levels(t, np.sin(t) * 6 + rng.normal(0.0, 1.0, len(t))) is None


def test_a_slow_ripple_the_armature_follows_is_not_averaged_away():
    """A supply rippling 5 % at 3 Hz under the duty, with 0.3 V of sensor noise: the steps are
    found, but the plateaus vary beyond their noise, so the voltage is not replaced by their
    means (the armature follows a 3 Hz ripple: the free-running regression needs it); at 137 Hz
    the averaged ripple is within the noise and the means stand."""
    rng = np.random.default_rng(5)
    t, duty = _steps(1000.0, 3.0, 9.0)
    for hz, averaged in ((3.0, False), (137.0, True)):
        v = duty * (1 + 0.05 * np.sin(2 * np.pi * hz * t)) + rng.normal(0.0, 0.3, len(t))
        assert len(held_steps(t, v)) == 2
        assert (held_levels(t, v) is not None) == averaged, hz


def test_at_start_needs_a_held_first_plateau():
    """``at_start`` (the rotor at rest at the first sample): a first plateau is a step from 0
    only where the input holds it. A measured voltage that sags and recovers with the load
    current (0 -> 12 -> 0 V, no single jump the noise lets through at every scale) is no
    plateau: before, the whole log was one "step" to its mean, 5 V, fitted with a dead time
    of a second."""
    rng = np.random.default_rng(3)
    t = np.arange(7000) / 1000.0
    cmd = np.where((t >= 1) & (t < 4), 12.0, 0.0)
    sag = np.where(cmd > 0, 3.0 * np.exp(-(t - 1) / 0.5), 0.0)
    u = cmd - sag + rng.normal(0, 0.3, t.size)
    for s in _found_or_none(t, u):
        assert abs(s.after - np.mean(u)) > 1.0  # never the whole log's mean
    held = np.full(t.size, 6.0) + rng.normal(0, 0.3, t.size)
    assert find_steps(t, held, at_start=True)[0].after == pytest.approx(6.0, abs=0.05)


def _found_or_none(t, u):
    try:
        return find_steps(t, u, at_start=True)
    except FitError:
        return []


@pytest.mark.parametrize("blend", [0.2, 0.5, 0.8])
def test_a_step_whose_change_falls_inside_a_sample_is_held(blend):
    """A loop-timed log put on a uniform grid holds each row's input from its instant: the
    sample the change falls in is a blend of the two levels. Wherever in the sample the change
    fell, the log is one held step (before: with the blend nearer the first level, the level
    before the step was not flat and the log was called rich; bench/newrigs.py lego seed 23)."""
    t = np.arange(150) * 0.01
    u = np.r_[np.zeros(20), blend * 2.7, np.full(129, 2.7)]
    steps = held_steps(t, u)
    assert len(steps) == 1 and steps[0].after == pytest.approx(2.7)
    # a ramp through the same levels is still no held step
    assert held_steps(t, np.clip((t - 0.1) * 5.0, 0.0, 2.7)) == []
