"""Signals on offset clocks (docs/io.md, 'Clocks'): a blocked-rotor current sampled on its own
clock, a fraction of a period after each command, is put on its own clock (compared where it
was taken, the voltage averaged over each step) and fit-electrical finds the same R, L as from
aligned clocks; the speed under a voltage stays interpolated on the command's clock."""

import numpy as np
import pytest

from bench.clock_offset import offset_logs, truth
from pmdcid.identify.electrical import fit_electrical
from pmdcid.identify.steps import find_steps
from pmdcid.io import parse_mapping, read_log

AMPLITUDES = (2.0, 4.0, 6.0)


def _fit(folder, offset, seed):
    rng = np.random.default_rng(seed)
    paths = offset_logs(str(folder), truth(), offset, rng, True, AMPLITUDES, 0.15)
    with pytest.warns(UserWarning):
        logs = [read_log(p, parse_mapping(["v=/cmd.volts", "i=/sensor.i"])) for p in paths]
    res = fit_electrical(logs)
    return {k: res.estimates[k].value for k in ("R", "L")}, logs


@pytest.mark.parametrize("offset", [0.3, 0.5])
def test_offset_current_is_compared_where_taken(tmp_path, offset):
    aligned, _ = _fit(tmp_path, 0.0, 7)
    got, logs = _fit(tmp_path, offset, 7)
    log = logs[0]
    assert "on the clock of '/sensor.i'" in log.notes[0]
    assert "held and averaged over each step" in log.notes[0]
    # the grid is the current's own instants: the current exactly as taken (MCAP's ns stamps)
    assert log.t_file[0] == pytest.approx(offset * 1e-3, abs=1e-9)
    # the voltage edge 0.05 s falls inside a step: found at its instant from the averaged sample
    assert find_steps(log.t_file, log.u)[0].t0 == pytest.approx(0.05, abs=1e-9)
    vals = truth()
    for k in ("R", "L"):
        assert got[k] == pytest.approx(aligned[k], rel=2e-3), k
        assert got[k] == pytest.approx(vals[k], rel=5e-3), k


def test_speed_under_a_voltage_stays_on_the_command_clock(tmp_path):
    """The speed's slope does not jump at a voltage step: interpolated at second order, the
    input exact on its own clock (nothing changes for free-speed logs)."""
    rng = np.random.default_rng(3)
    p = offset_logs(str(tmp_path), truth(), 0.3, rng, False, (3.0,), 0.3)[0]
    with pytest.warns(UserWarning, match="put on the input's clock"):
        log = read_log(p, parse_mapping(["v=/cmd.volts", "omega=/sensor.omega"]))
    assert log.resampled is None and set(np.unique(log.u)) <= {0.0, 3.0}


def test_averaged_edge_found_inside_the_step():
    """find_steps on a noise-free input with one sample between the levels (an edge inside
    that sample's step, averaged): the edge where the input's integral puts it."""
    t = np.arange(40) * 1e-3
    u = np.where(t >= 0.0203, 2.0, 0.0)
    u[20] = 2.0 * 0.7  # mean over [20 ms, 21 ms) of an edge at 20.3 ms
    assert find_steps(t, u)[0].t0 == pytest.approx(0.0203)
    u[20] = 0.0  # a plain held step: its sample's instant
    assert find_steps(t, u)[0].t0 == pytest.approx(0.021)
