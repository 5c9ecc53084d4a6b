"""io/clock.py: loop-timed logs on a uniform grid (input held, measurements interpolated) and
what stays refused; round trips on a jittered time base against the exact simulation."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import REAL

from pmdcid.cli import main
from pmdcid.errors import LogError
from pmdcid.io import Log, read_log, write_log
from pmdcid.io.clock import WITHIN_PARTS, examine, held_mean, merged
from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.synth import PAPER

#: the fine grid the truth is simulated on [s]: every logged instant is one of its points
FINE = 1e-4


def loop_instants(rng, seconds):
    """Loop-timed instants [s] as an EV3 loop logs them: 4-6 ms apart, one in seven 6-18 ms."""
    n = int(seconds / 4e-3) + 2
    steps = np.where(rng.uniform(size=n) < 1 / 7, rng.integers(60, 181, n),
                     rng.integers(40, 61, n))
    k = np.cumsum(steps)
    k = np.concatenate(([0], k))
    return k[k * FINE <= seconds]


def exact_fine(rng, vals, seconds=2.0, levels=(0.0, 1.5, 2.5, -1.0, 2.0)):
    """A motor simulated on the fine grid under an input that changes only at loop instants
    (held between them, as the loop applied it): (loop instants as fine indices, the input at
    them, the simulation on the fine grid)."""
    k = loop_instants(rng, seconds)
    nfine = int(k[-1]) + 1
    u_at = np.repeat(np.asarray(levels), int(np.ceil(len(k) / len(levels))))[:len(k)]
    u_at = np.roll(u_at, len(k) // (2 * len(levels)))  # edges away from the first sample
    u_fine = u_at[np.searchsorted(k, np.arange(nfine), side="right") - 1]
    return k, u_at, simulate_values(np.arange(nfine) * FINE, u_fine, vals)


def exact_log(rng, vals, seconds=2.0, levels=(0.0, 1.5, 2.5, -1.0, 2.0)):
    """:func:`exact_fine`'s speed, angle and current sampled at the loop instants."""
    k, u_at, sim = exact_fine(rng, vals, seconds, levels)
    return k * FINE, u_at, sim.omega[k], sim.theta[k], sim.i[k]


def test_uniform_log_is_unchanged(rng):
    t = np.arange(500) * 1e-3 + rng.uniform(-5e-6, 5e-6, 500)
    c = examine(t, "x")
    assert c.uniform and len(c.grid) == 500 and c.period == pytest.approx(1e-3, rel=1e-3)


def test_held_mean_is_exact_for_a_held_input(rng):
    ts = np.cumsum(rng.uniform(0.004, 0.018, 300))
    u = rng.normal(size=300)
    grid = ts[0] + 0.005 * np.arange(int((ts[-1] - ts[0]) / 0.005))
    got = held_mean(ts, u, grid)
    # the integral of the held input over each step, by brute force on a 1 us grid
    fine = np.arange(grid[0], grid[-1], 1e-6)
    uf = u[np.searchsorted(ts, fine, side="right") - 1]
    k = np.minimum(((fine - grid[0]) / 0.005).astype(int), len(grid) - 2)
    ref = np.bincount(k, uf) / np.bincount(k)
    np.testing.assert_allclose(got[:-1], ref, atol=2e-3 * np.abs(u).max())


def test_held_mean_keeps_a_held_level_exactly(rng):
    """A duty held at one level (a step applied at the first sample, loop-timed instants 4-18 ms
    apart): every step of the grid holds exactly that level, so the log's input never changes
    (the running area's difference had left 1e-16 ripples: the step read as an input that
    varies between its samples). Where the level changes inside a step, its mean lies between."""
    ts = np.cumsum(rng.uniform(0.004, 0.018, 400))
    grid = ts[0] + 0.00509 * np.arange(int((ts[-1] - ts[0]) / 0.00509))
    held = held_mean(ts, np.full(400, 0.729), grid)
    assert np.all(held == 0.729)
    u = np.where(np.arange(400) < 200, 0.729, -0.3)
    got = held_mean(ts, u, grid)
    change = np.searchsorted(grid, ts[200]) - 1
    assert np.all(got[:change] == 0.729) and np.all(got[change + 1:] == -0.3)
    assert -0.3 <= got[change] <= 0.729


def test_loop_timed_state_error_is_small(rng, paper_values):
    """The kernel on the ~5 ms grid (the input's mean per step) against the exact simulation
    with the input held from each loop instant (4-18 ms apart), read back at the loop instants:
    within 1.5 % of the speed's range everywhere and 0.5 % NRMSE (measured: 0.4-0.5 % and
    0.2-0.3 % over seeds 1, 2, 3, 12345; docs/io.md, 'Clocks')."""
    t, u, om, th, i = exact_log(rng, paper_values)
    log = Log.from_arrays(t, v=u, omega=om, theta=th, i=i)
    assert log.resampled is not None and "loop-timed" in log.notes[0]
    sim = simulate_values(log.t, log.u, paper_values)
    back = log.resampled.at_file_instants({"omega": sim.omega})["omega"]
    err = np.abs(back - om)
    assert err.max() <= 0.015 * np.ptp(om)
    assert np.sqrt(np.mean(err ** 2)) <= 0.005 * np.std(om)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_dead_zone_sees_each_edge_where_the_loop_applied_it(seed, paper_values):
    """Through a dead zone just under the smallest level (0.018 N m, 85 % of the torque of the
    1 V steps at rest), an edge sample's mean over the whole step (a blend of 0 and 1 V: under
    the dead zone, no torque) delays each start; the input held inside each sample
    (Log.input_within, 16 parts) places the edge to within dt/16. On the grid against the exact
    simulation (the loop's input held from its instants, 0.1 ms steps): the speed within 0.1 %
    of its range everywhere where the whole-step mean is off by 5 times as much or more
    (measured 0.006-0.012 % against 0.7-1.4 % over seeds 1-3)."""
    vals = {**paper_values, "dz": 0.018}
    k, u, fine = exact_fine(np.random.default_rng(seed), vals, levels=(0.0, 1.0, 0.0, -1.0, 1.0))
    log = Log.from_arrays(k * FINE, v=u, omega=fine.omega[k])
    within = log.input_within()
    assert within is not None and len(within) == WITHIN_PARTS * log.n
    np.testing.assert_allclose(within.reshape(log.n, -1).mean(axis=1), log.u, atol=1e-12)
    truth = np.interp(log.t + log.resampled.grid[0], np.arange(len(fine.omega)) * FINE,
                      fine.omega)
    err = {}
    for name, w in (("within", within), ("mean", None)):
        sim = simulate_values(log.t, log.u, vals, within=w)
        err[name] = np.abs(sim.omega - truth).max() / np.ptp(truth)
    assert err["within"] <= 0.001, err
    assert err["mean"] >= 5 * err["within"], err


def test_the_input_within_samples_only_where_it_changes_inside_one(rng):
    """A uniform log, a loop-timed log whose input changes only at grid instants, and a log cut
    after reading (its samples no longer the resampling's) step the held samples (None)."""
    t = np.arange(200) * 0.01
    assert Log.from_arrays(t, v=np.where(t > 0.5, 1.0, 0.0), omega=0 * t).input_within() is None
    tl = np.concatenate((np.arange(100) * 0.005, 0.5 + np.cumsum(rng.uniform(0.004, 0.006, 50))))
    log = Log.from_arrays(tl, v=np.where(tl > 0.3, 1.0, 0.0), omega=0 * tl)
    assert log.resampled is not None
    assert log.input_within() is None  # the edge at 0.3 s, a grid instant: no blend
    log = Log.from_arrays(tl, v=np.where(tl > 0.6, 1.0, 0.0), omega=0 * tl)
    assert log.input_within() is not None
    log.data["v"] = log.u[::-1].copy()  # changed after reading
    assert log.input_within() is None


def test_round_trip_fit_on_a_jittered_time_base(rng):
    """Simulate the paper's motor (J, bv, bc moved) on 4-18 ms loop instants with noise, fit
    fit-mechanical, get the truth back: J, bv within 3 %, bc within 10 % (bc is small against
    the torque at these voltages: its own standard error is ~5 %)."""
    from pmdcid.identify.mechanical import fit_mechanical
    from pmdcid.model import Model

    vals = {**neutral_values(), **PAPER}
    vals.update(J=PAPER["J"] * 1.2, bv=PAPER["bv"] * 0.8, bc=PAPER["bc"] * 1.1)
    logs = []
    for level in (1.0, 2.0):
        t, u, om, th, i = exact_log(rng, vals, seconds=1.5, levels=(0.0, level, level, level))
        om = om + rng.normal(0, 4e-3, len(om))
        logs.append(Log.from_arrays(t, v=u, omega=om, name=f"loop_{level}V"))
    m = Model()
    for k in ("R", "L", "km"):
        m.set(k, vals[k], stage="truth")
    res = fit_mechanical(logs, m, joint=True)
    assert res.estimates["J"].value == pytest.approx(vals["J"], rel=0.03)
    assert res.estimates["bv"].value == pytest.approx(vals["bv"], rel=0.03)
    assert res.estimates["bc"].value == pytest.approx(vals["bc"], rel=0.10)


def test_repeated_stamps_merged_within_the_rule(rng):
    t = np.cumsum(rng.uniform(0.004, 0.018, 400))
    t[50] = t[49]  # the loop ran twice within the clock's resolution
    v = np.ones(400)
    v[49], v[50] = 0.5, 2.0
    om = np.linspace(0, 10, 400)
    log = Log.from_arrays(t, v=v, omega=om)
    assert "1 repeated time stamp(s) merged" in log.notes[0]
    c = examine(t, "x")
    assert merged(v, c.groups, held=True)[49] == 2.0  # the loop's last command holds
    assert merged(om, c.groups, held=False)[49] == pytest.approx((om[49] + om[50]) / 2)


@pytest.mark.parametrize("edit, message", [
    (lambda t: np.concatenate((t[:100], t[100:] - 0.05)), "time goes back at data row 101"),
    (lambda t: np.repeat(t, 2)[:len(t)], r"time stands still in \d+ rows .* more than 5 %"),
    (lambda t: np.concatenate((t[:100], t[100:] + 0.5)),
     r"a gap of 0\.5\d* s after data row 100 .* more than 10 x the median interval"),
])
def test_broken_loop_timed_logs_refused(rng, edit, message):
    t = edit(np.cumsum(rng.uniform(0.004, 0.018, 400)))
    with pytest.raises(LogError, match=message):
        Log.from_arrays(t, v=np.ones(len(t)), omega=np.ones(len(t)), name="loop.csv")


def test_uniform_logger_with_bad_rows_still_refused():
    t = np.arange(3000) * 1e-3
    with pytest.raises(LogError, match="samples missing"):
        Log.from_arrays(np.delete(t, np.s_[1000:1003]), v=np.ones(2997), omega=np.ones(2997))
    t2 = t.copy()
    t2[20] = t2[19]
    with pytest.raises(LogError, match="time stands still at data row 21"):
        Log.from_arrays(t2, v=np.ones(3000), omega=np.ones(3000))


def test_simulate_keeps_a_loop_timed_input_t_column(tmp_path, rng):
    t, u, om, th, i = exact_log(rng, {**neutral_values(), **PAPER}, seconds=1.0)
    inp = tmp_path / "loop.csv"
    write_log(inp, t + 0.123, {"v": u, "omega": om})
    model = tmp_path / "m.json"
    model.write_text(json.dumps({"parameters": {k: {"value": v} for k, v in PAPER.items()}}))
    out = tmp_path / "out.csv"
    res = CliRunner().invoke(main, ["simulate", str(inp), "-m", str(model), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert "loop-timed samples" in res.output
    rows = np.loadtxt(out, delimiter=",", comments="#", skiprows=4)
    np.testing.assert_array_equal(rows[:, 0], np.loadtxt(inp, delimiter=",", skiprows=1)[:, 0])
    np.testing.assert_array_equal(rows[:, 1], u)
    # noise-free: the simulated speed is the exact one within the stated bound (1 % of range)
    assert np.max(np.abs(rows[:, 3] - om)) < 0.01 * np.ptp(om)


def test_lego_ev3_step_reads_as_loop_timed():

    p = REAL / "lego-ev3/step_+50.csv"
    if not p.parent.exists():
        pytest.skip("../shared/data/real/lego-ev3 is absent")
    log = read_log(p)
    assert log.resampled is not None and log.dt == pytest.approx(0.0051, abs=3e-4)
    assert log.derived == {"omega"} and len(log.resampled.t_file) == 937
    # fit-mechanical runs on the steps (applied from the first sample, from rest)
    from pmdcid.identify.runners import lumped_if_wanted, stage_mechanical
    from pmdcid.model import Model

    logs = [read_log(p.parent / f"step_{s}.csv") for s in ("+30", "+60", "-60", "+90")]
    res = stage_mechanical(logs, lumped_if_wanted(logs, Model()))
    assert all(s.moved and s.t0 == 0.0 for s in res.steps)
    assert 0 < res.estimates["J"].value < res.estimates["bv"].value  # tau_m ~ 0.07 s


def test_rows_out_of_order_are_told_apart_from_a_counter_wrap():
    t = np.arange(3000) * 1e-3
    swapped = t.copy()
    swapped[[1500, 1501]] = swapped[[1501, 1500]]  # one pair of rows written in the wrong order
    with pytest.raises(LogError, match=r"time goes back at data row 1502 \(t=1\.5 s\): rows out "
                                       r"of order at t = 1\.501 s .*: sort the log by time$"):
        Log.from_arrays(swapped, v=np.ones(3000), omega=np.ones(3000))
    wrapped = np.mod(np.arange(3000) * 30, 2**16) * 1e-3  # a 16-bit ms counter, 30 ms apart
    with pytest.raises(LogError, match="a 16-bit millisecond counter that overflows"):
        Log.from_arrays(wrapped, v=np.ones(3000), omega=np.ones(3000))
    backwards = t[::-1].copy()
    with pytest.raises(LogError, match="the rows are in reverse order: sort the log by time"):
        Log.from_arrays(backwards, v=np.ones(3000), omega=np.ones(3000))
