"""The input read between its samples (simulate/input_grid.ramp_input): exact averages of a blend of
the held and the linear reading, on the fine grid the late input uses."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pmdcid.simulate import neutral_values, param_vector, simulate_values
from pmdcid.simulate.input_grid import MAX_PARTS, inner_steps, late_input, parts_for, ramp_input
from pmdcid.simulate.substeps import MAX_MECH_SUBSTEPS, choose_substeps, max_step, substeps_for


def _u(seed: int, n: int = 40) -> np.ndarray:
    return np.random.default_rng(seed).normal(0.0, 2.0, n)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 0.05), st.integers(1, 12))
def test_held_reading_is_the_late_input(seed, latency, q):
    u = _u(seed)
    got = ramp_input(u, 0.01, latency, 0.0, q)
    assert np.max(np.abs(got - late_input(u, 0.01, latency, q))) < 1e-12 * np.ptp(u) * 10


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 12))
def test_linear_reading_holds_each_fine_intervals_mean(seed, q):
    """ramp = 1: the fine interval j of sample k holds u_k + (u_k+1 - u_k) (j + 1/2)/q, the
    mean of the straight line between the samples; after the last sample the input is held."""
    u = _u(seed)
    nxt = np.append(u[1:], u[-1])
    frac = (np.arange(q) + 0.5) / q
    want = (u[:, None] + (nxt - u)[:, None] * frac[None, :]).ravel()
    got = ramp_input(u, 0.01, 0.0, 1.0, q)
    assert np.max(np.abs(got - want)) < 1e-9 * np.ptp(u)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 1.0), st.integers(1, 6), st.integers(2, 8))
def test_a_latency_of_whole_fine_intervals_shifts_the_blend(seed, ramp, shift, q):
    u = _u(seed)
    dt = 0.01
    base = ramp_input(u, dt, 0.0, ramp, q)
    late = ramp_input(u, dt, shift * dt / q, ramp, q)
    np.testing.assert_allclose(late[shift:], base[:-shift], atol=1e-9 * np.ptp(u))
    np.testing.assert_allclose(late[:shift], u[0], atol=1e-9 * np.ptp(u))


def test_blend_is_linear_in_ramp():
    u = _u(3)
    a, b = ramp_input(u, 0.02, 0.003, 0.0, 8), ramp_input(u, 0.02, 0.003, 1.0, 8)
    mid = ramp_input(u, 0.02, 0.003, 0.3, 8)
    np.testing.assert_allclose(mid, 0.7 * a + 0.3 * b, atol=1e-9 * np.ptp(u))


def test_profile_minimum_and_width():
    """A parabolic profile: its minimum and the half-width where it rises by the scale; a
    profile falling steeply from one end: the lowest end, not a least-squares compromise; a
    flat one: the uniform spread of the range."""
    from pmdcid.identify.ramp_profile import RAMPS, parabola_minimum

    x = np.array(RAMPS)
    m, w = parabola_minimum(x, 1000 + 400 * (x - 0.6) ** 2, 1.0)
    assert m == pytest.approx(0.6, abs=1e-9) and w == pytest.approx(0.05, rel=1e-9)
    m, _ = parabola_minimum(x, np.array([2451.0, 1116.9, 1103.1, 1095.4, 1092.3]), 1.0)
    assert m == 1.0
    m, w = parabola_minimum(x, np.full(5, 7.0), 1.0)
    assert w == pytest.approx(1 / np.sqrt(12))


def test_the_fine_input_is_kept_only_while_the_log_holds_its_values():
    """fine_input keeps what it built for the next evaluation of the same log, and builds afresh
    when the logged array changed in place: never a stale input."""
    from pmdcid.simulate.input_grid import fine_input

    rng = np.random.default_rng(3)
    u = rng.normal(size=200)
    first = fine_input(u, 0.01, 0.0, 0.5, 8)
    assert fine_input(u, 0.01, 0.0, 0.5, 8) is first
    assert not first.flags.writeable
    np.testing.assert_array_equal(first, ramp_input(u, 0.01, 0.0, 0.5, 8))
    u[50] += 1.0
    again = fine_input(u, 0.01, 0.0, 0.5, 8)
    np.testing.assert_array_equal(again, ramp_input(u, 0.01, 0.0, 0.5, 8))
    late = fine_input(u, 0.01, 0.004, None, 8)
    np.testing.assert_array_equal(late, late_input(u, 0.01, 0.004, 8))


def test_a_stiff_model_reads_a_late_input_on_a_bounded_grid():
    """A model that asks for many internal steps a sample (a fit trying a J near 0 on a 2 kHz
    real ramp, fra233-g04's ramp_1.csv, asked for 39019, and the late input's fine grid and its
    states for 8001 samples took 18 GB before the kernel ran: identify was killed) reads its
    late input on at most MAX_PARTS fine intervals a sample, the kernel's internal steps inside
    each: a latency of one whole sample still shifts the simulation by exactly one sample."""
    vals = {**neutral_values(), "R": 1.0, "L": 1e-3, "km": 0.05, "ke": 0.05, "J": 2e-7,
            "bv": 1e-5, "bc": 0.0, "dz": 0.0}
    nsub = 1000
    assert parts_for(nsub) == MAX_PARTS and MAX_PARTS * inner_steps(nsub, MAX_PARTS) >= nsub
    dt = 1e-3
    t = np.arange(400) * dt
    u = 6.0 * np.sin(2 * np.pi * 5.0 * t)  # from 0: at rest before the log as in it
    plain = simulate_values(t, u, vals, nsub=nsub).omega
    late = simulate_values(t, u, {**vals, "latency": dt}, nsub=nsub).omega
    np.testing.assert_allclose(late[1:], plain[:-1], atol=1e-9 * float(np.ptp(plain)))


def test_a_rotor_faster_than_a_fifth_of_a_sample_takes_at_most_the_capped_steps():
    """J/bv under a fifth of a sample: the mechanics' own rule (50 steps a time constant) would
    ask for 625 internal steps a sample here, and a fit trying J near 0 on a slow real ramp for
    thousands (fra233-g04's ramp_3.csv: identify stopped on the work bound, blaming the time
    unit). Capped at MAX_MECH_SUBSTEPS, the sampled speed is the finely stepped one's to a
    thousandth of its range (the linear step is exact; a stop is placed within a step)."""
    vals = {**neutral_values(), "R": 1.0, "L": 1e-4, "km": 0.05, "ke": 0.05, "J": 2e-7,
            "bv": 1e-5, "bc": 0.02, "dz": 0.0}
    dt = 1e-3
    p = param_vector(vals)
    assert substeps_for(dt, max_step(p)) > 2 * MAX_MECH_SUBSTEPS
    assert choose_substeps(dt, p) == MAX_MECH_SUBSTEPS
    t = np.arange(400) * dt
    u = 6.0 * np.sin(2 * np.pi * 5.0 * t)  # through zero: the rotor stops and starts again
    capped = simulate_values(t, u, vals).omega
    fine = simulate_values(t, u, vals, nsub=substeps_for(dt, max_step(p))).omega
    assert np.any(capped == 0.0)
    np.testing.assert_allclose(capped, fine, atol=1e-3 * float(np.ptp(fine)))
