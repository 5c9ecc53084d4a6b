"""MATLAB files as scripts save them, beyond one vector per variable: each written with
scipy.io.savemat (v5) or h5py (v7.3, as MATLAB lays it out), then read."""

from __future__ import annotations

import numpy as np
import pytest
from read_util import STEP_N, step_motor

N = STEP_N



@pytest.mark.parametrize("rows", [False, True])
def test_matrix_one_signal_a_row(tmp_path, rows):
    """``data = [t; v; w]`` (3 x N, a signal a row): before, 'holds no numeric signal a motor
    log could use' (N columns taken for N signals, more than a matrix of signals has); now the
    same as the N x 3 matrix ``[t, v, w]``."""
    sio = pytest.importorskip("scipy.io")
    from pmdcid.io import parse_mapping, read_log

    t, v, w = step_motor(21)
    data = np.vstack([t, v, w]) if rows else np.column_stack([t, v, w])
    p = tmp_path / "log.mat"
    sio.savemat(p, {"data": data})
    log = read_log(p, parse_mapping(["t=data[0]", "v=data[1]", "omega=data[2]"]))
    assert log.n == N and log.dt == pytest.approx(1e-3)
    np.testing.assert_array_equal(log["v"], v)
    np.testing.assert_array_equal(log["omega"], w)


def test_canonical_variable_of_another_length_is_named(tmp_path):
    """``t`` and ``v`` with 2000 samples, ``omega`` with 200 (a decimated speed, saved as it
    was): before, ``omega`` was dropped without a word and the command said it 'needs
    column(s) omega ... it has v', as if the file held no speed; now one line names it."""
    sio = pytest.importorskip("scipy.io")
    from click.testing import CliRunner
    from repo_paths import FIXTURES

    from pmdcid.cli import main

    rng = np.random.default_rng(22)
    t = np.arange(2000) * 1e-3
    v = np.where(t >= 0.5, 6.0, 0.0)
    w = 60.0 * (1 - np.exp(-np.clip(t - 0.5, 0, None) / 0.1))
    p = tmp_path / "log.mat"
    sio.savemat(p, {"t": t, "v": v, "omega": w[::10] + rng.normal(0, 0.02, 200)})
    said = (f"error: {p}: 'omega' has 200 samples where the time column 't' has 2000: the "
            "columns of a .mat log share its time column, so it cannot be used as it is (save "
            "'omega' at the time column's instants)")
    truth = FIXTURES / "paper" / "truth.json"
    for args in (["fit-mechanical", p, "-m", tmp_path / "m.json", "--km", "0.05"],
                 ["plan", "--check", p, "-m", truth, "-o", tmp_path / "pl"]):
        res = CliRunner().invoke(main, [str(a) for a in args])
        assert res.exit_code == 1 and res.stderr.strip().splitlines() == [said], res.stderr
