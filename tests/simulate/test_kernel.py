"""The shared kernel: exact against the linear transfer function, convergent, true stiction."""

import numpy as np
import pytest
from scipy import signal

from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.synth import staircase, triangle


def linear_reference(t, v, vals):
    """Paper eq. (5) with back-EMF, computed independently with scipy.signal (ZOH input)."""
    R, L, km, J, bv, ke = (vals[k] for k in ("R", "L", "km", "J", "bv", "ke"))
    # omega/V = km / ((L s + R)(J s + bv) + km ke)
    num = [km]
    den = np.polyadd(np.polymul([L, R], [J, bv]), [km * ke])
    sys = signal.TransferFunction(num, den).to_ss()
    dt = t[1] - t[0]
    dsys = signal.cont2discrete((sys.A, sys.B, sys.C, sys.D), dt, method="zoh")
    _, y, _ = signal.dlsim(dsys[:4] + (dt,), v, t=t)
    return y[:, 0]


@pytest.mark.parametrize("ke", [0.0, 50.2e-3])
@pytest.mark.parametrize("nsub", [1, 3])
def test_linear_case_matches_transfer_function(paper_values, ke, nsub, rng):
    vals = {**paper_values, "bc": 0.0, "dz": 0.0, "ke": ke}
    t = np.arange(20000) * 1e-3
    v = staircase(t, 2.0, 0.37, rng)
    sim = simulate_values(t, v, vals, nsub=nsub)
    ref = linear_reference(t, v, vals)
    err = np.max(np.abs(sim.omega - ref)) / np.max(np.abs(ref))
    assert err < 1e-6


def test_converges_as_step_shrinks(paper_values):
    vals = {**paper_values, "fs": 2e-3, "ws": 0.1, "ca": 1e-3, "cn": 7.0}
    t = np.arange(8000) * 1e-3
    v = triangle(t, 2.0, 4.0)
    ref = simulate_values(t, v, vals, nsub=256).omega
    errs = [np.sqrt(np.mean((simulate_values(t, v, vals, nsub=n).omega - ref) ** 2))
            for n in (2, 8, 32)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 0.25 * errs[0]
    assert errs[2] / np.std(ref) < 1e-3


def test_rotor_below_static_friction_stays_exactly_at_rest(paper_values):
    # torque km*v/R below bc and dz: the rotor must not creep at all
    vals = {**paper_values, "dz": 0.0}
    v_stuck = 0.9 * vals["bc"] * vals["R"] / vals["km"]
    t = np.arange(3000) * 1e-3
    sim = simulate_values(t, np.full_like(t, v_stuck), vals)
    assert np.all(sim.omega == 0.0) and np.all(sim.theta == 0.0)
    assert sim.i[-1] == pytest.approx(v_stuck / vals["R"], rel=1e-9)
    # just above it moves, at the Coulomb-limited speed
    v_move = 1.5 * vals["bc"] * vals["R"] / vals["km"]
    sim = simulate_values(t, np.full_like(t, v_move), vals)
    expect = (vals["km"] * v_move / vals["R"] - vals["bc"]) / vals["bv"]
    assert sim.omega[-1] == pytest.approx(expect, rel=1e-6)


def test_dead_zone_blocks_torque_below_break_point(paper_values):
    vals = {**paper_values, "bc": 1e-4}
    v_in = 0.95 * vals["dz"] * vals["R"] / vals["km"]
    t = np.arange(2000) * 1e-3
    sim = simulate_values(t, np.full_like(t, v_in), vals)
    assert np.all(sim.omega == 0.0)


@pytest.mark.xfail(strict=True, reason="the kernel takes the dead zone's mode at each internal "
                   "step's start: it chatters at the edge, on steps of h/16 where a step crosses "
                   "it (ripple 0.39 -> 0.094 rad/s, the slope's jitter 7.3 % -> 0.31 %; a sliding "
                   "edge was tried in session 17 and not kept: docs/model.md)")
def test_dead_zone_above_running_friction_pins_torque_at_its_edge():
    # dz above what the running rotor needs (bc + bv w): the current is held at the edge,
    # i = dz/km, so the speed settles exactly at (v - R dz/km)/ke (Filippov sliding), and it
    # moves smoothly with dz. A step that takes its mode from its start chatters in and out
    # of the dead zone instead (0.4 rad/s ripple, the slope in dz jittering by 15 %): the
    # kernel does that today
    vals = {**neutral_values(), "R": 5.0, "L": 0.01, "km": 0.01, "ke": 0.01, "J": 2e-6,
            "bv": 1e-7, "bc": 2e-4, "dz": 4e-4}
    t = np.arange(2000) * 1e-3
    v = np.full_like(t, 3.0)
    w = simulate_values(t, v, vals).omega
    pinned = (3.0 - vals["R"] * vals["dz"] / vals["km"]) / vals["ke"]
    assert w[-500:] == pytest.approx(np.full(500, pinned), rel=1e-6)
    ends = [np.mean(simulate_values(t, v, {**vals, "dz": dz}).omega[-1000:])
            for dz in np.linspace(3.9e-4, 4.1e-4, 21)]
    slope = np.diff(ends)
    assert np.all(slope < 0) and np.std(slope) < 1e-3 * abs(np.mean(slope))


def test_stick_slip_stops_and_holds_on_triangle(paper_values):
    t = np.arange(40000) * 1e-3
    sim = simulate_values(t, triangle(t, 2.0, 40.0), paper_values)
    rest = sim.omega == 0.0
    assert 0.05 < rest.mean() < 0.4  # dwell at zero speed around each reversal
    held = rest[1:] & rest[:-1]
    assert np.all(np.diff(sim.theta)[held] == 0.0)
    # symmetric input, symmetric response
    assert sim.omega.max() == pytest.approx(-sim.omega.min(), rel=1e-3)


def test_torque_driven_matches_first_order(paper_values):
    vals = {**paper_values, "bc": 0.0, "dz": 0.0}
    t = np.arange(2000) * 1e-3
    tau = np.full_like(t, 0.02)
    sim = simulate_values(t, tau, vals, torque_driven=True)
    tm = vals["J"] / vals["bv"]
    ref = 0.02 / vals["bv"] * (1 - np.exp(-t / tm))
    assert np.max(np.abs(sim.omega - ref)) < 1e-9 * 0.02 / vals["bv"] + 1e-12
    assert np.all(np.isnan(sim.i))


def test_sensor_effects(paper_values):
    t = np.arange(3000) * 1e-3
    v = np.where(t > 0.5, 1.0, 0.0)
    base = simulate_values(t, v, paper_values)
    late = simulate_values(t, v, {**paper_values, "delay": 0.01, "omega0": 0.05})
    assert np.allclose(late.omega[20:] - 0.05, base.omega[10:-10], atol=1e-12)
    assert np.allclose(late.theta[20:], base.theta[10:-10], atol=1e-12)


@pytest.mark.parametrize("scale", [1e-3, 1.0, 50.0, 3e3])
def test_compiled_expm_matches_scipy(scale, rng):
    from scipy.linalg import expm

    from pmdcid.simulate.kernel import expm_small

    M = rng.normal(size=(6, 6)) * scale
    M[3:, :] = 0.0
    M[:3, :3] -= np.eye(3) * scale  # stable block, as the motor's A
    ref = expm(M)
    E = np.empty((6, 6))
    expm_small(M, E)
    assert np.allclose(E, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())


def test_viscous_asymmetry_steady_speeds(paper_values):
    """Constant torque T above Coulomb: the rotor settles at (T - bc)/(bv + dbv) forward and
    -(T - bc)/(bv - dbv) backward; dbv = 0 (neutral) gives the symmetric model exactly."""
    t = np.arange(20000) / 1000.0  # 20 s >> J/bv ~ 0.1 s
    vals = {**paper_values, "dz": 0.0}
    T, dbv = 0.02, 0.01
    base = simulate_values(t, np.full(len(t), T), vals, torque_driven=True).omega
    off = simulate_values(t, np.full(len(t), T), {**vals, "dbv": 0.0}, torque_driven=True).omega
    assert np.array_equal(base, off)
    fwd = simulate_values(t, np.full(len(t), T), {**vals, "dbv": dbv}, torque_driven=True).omega
    bwd = simulate_values(t, np.full(len(t), -T), {**vals, "dbv": dbv}, torque_driven=True).omega
    assert fwd[-1] == pytest.approx((T - vals["bc"]) / (vals["bv"] + dbv), rel=1e-6)
    assert bwd[-1] == pytest.approx(-(T - vals["bc"]) / (vals["bv"] - dbv), rel=1e-6)


def test_compiled_cache_is_stamped_with_its_sources():
    """The numba cache is cleared when the inlined physics changes (pmdcid.simulate.cache):
    right after import the stamp matches the sources, so nothing more is removed."""
    from pmdcid.simulate.cache import invalidate_if_stale

    assert invalidate_if_stale() is False


def test_output_buffer_gives_the_same_states_and_is_reused(paper_values):
    from pmdcid.simulate import param_vector
    from pmdcid.simulate.kernel import run_kernel
    from pmdcid.simulate.layout import NSTATE

    t = np.arange(20000) / 1000.0
    u = triangle(t, 2.0, 10.0)
    p = param_vector(paper_values)
    ref = run_kernel(u, 1e-3, p)
    buf = np.full((len(t), NSTATE), np.nan)
    got = run_kernel(u, 1e-3, p, out=buf)
    assert got is buf and got.tobytes() == ref.tobytes()
    sim = simulate_values(t, 0.5 * u, paper_values, out=buf)  # the buffer's next use
    assert sim.omega.tobytes() == simulate_values(t, 0.5 * u, paper_values).omega.tobytes()
    assert not np.array_equal(buf, ref)  # overwritten: a caller keeping a result must copy it
    with pytest.raises(ValueError, match="C-contiguous"):
        run_kernel(u, 1e-3, p, out=np.empty((len(t), NSTATE)).T.copy().T)


def _reversals(vals, n=4000):
    """A torque square wave, +-4 bc every 50 ms (torque-driven, no dead zone): the speed
    crosses zero inside an internal step at every reversal, never sticking there."""
    t = np.arange(n) * 1e-3
    return t, np.where((t // 0.05) % 2 == 0, 1.0, -1.0) * 4.0 * vals["bc"]


def test_a_speed_crossing_zero_inside_a_step_goes_on_through_it(paper_values):
    """At one internal step a sample (1 ms, J/bv 0.1 s) the speed through 80 reversals stays
    within 1e-4 of its spread of a 256-substep reference. Stopping at zero for the rest of the
    step (the kernel before session 22) lost up to a step at each: 2 % of the spread."""
    vals = {**paper_values, "dz": 0.0}
    t, tau = _reversals(vals)
    ref = simulate_values(t, tau, vals, torque_driven=True, nsub=256).omega
    one = simulate_values(t, tau, vals, torque_driven=True, nsub=1).omega
    assert np.sum(np.diff(np.sign(ref)) != 0) > 50
    assert np.sqrt(np.mean((one - ref) ** 2)) < 1e-4 * np.std(ref)


def test_the_state_after_a_reversal_is_continuous_in_the_friction(paper_values):
    """The angle after 0.4 s of reversals as bc moves over +-2 % in 200 steps: no step of the
    sweep jumps more than twice the median one, so a fit's central differences see no cliff
    where a crossing moves across an internal step's boundary (before session 22: a jump 500
    times the median, 450 chi-square units between neighbouring bc on a two-level PRBS)."""
    vals = {**paper_values, "dz": 0.0}
    t, tau = _reversals(vals, 400)
    ends = [simulate_values(t, tau, {**vals, "bc": b}, torque_driven=True, nsub=1).theta[-1]
            for b in vals["bc"] * (1.0 + np.linspace(-0.02, 0.02, 201))]
    jumps = np.abs(np.diff(ends))
    assert jumps.max() < 2.0 * np.median(jumps)


def _instant_motor():
    """A motor whose back-EMF is most of its damping, with Coulomb friction and a dead zone
    above it (per volt: R = km = 1): where the dead zone acts on v - ke w."""
    return {**neutral_values(), "R": 1.0, "km": 1.0, "ke": 0.9, "J": 0.05, "bv": 0.1,
            "bc": 0.3, "dz": 0.4}


@pytest.mark.parametrize("vb", [0.0, 0.2])
def test_an_instant_current_is_the_limit_of_a_vanishing_inductance(vb):
    """L = 0: the current follows (v - ke w)/R at once (terms.instant_current), the dead
    zone on it, the stick-slip as ever. Against L = 1 us stepped 2000 times a sample (the
    same motor, its lag 1e-4 of a sample) the speed agrees to 2e-4 of its range, on a
    triangle that starts, stops and reverses the rotor through the dead zone."""
    vals = {**_instant_motor(), "vb": vb}
    t = np.arange(800) * 0.01
    v = triangle(t, 8.0, 4.0)
    instant = simulate_values(t, v, {**vals, "L": 0.0})
    fine = simulate_values(t, v, {**vals, "L": 1e-6}, nsub=2000)
    assert np.max(np.abs(instant.omega - fine.omega)) < 2e-4 * np.ptp(fine.omega)
    assert np.ptp(fine.omega) > 10.0  # the rotor ran both ways
    assert np.count_nonzero(instant.omega == 0.0) > 20  # and stuck in between


def test_an_instant_current_is_recorded_as_the_voltage_drives_it():
    """The current recorded with L = 0 is (v - ke w)/R of the sample's start under the input
    held over the sample before (the state the kernel carried into it)."""
    vals = _instant_motor()
    t = np.arange(400) * 0.01
    v = triangle(t, 8.0, 4.0)
    sim = simulate_values(t, v, {**vals, "L": 0.0})
    expect = (v[:-1] - vals["ke"] * sim.omega[1:]) / vals["R"]
    assert np.allclose(sim.i[1:], expect, atol=1e-12)
