"""MATLAB files as scripts save them, beyond one vector per variable: each written with
scipy.io.savemat (v5) or h5py (v7.3, as MATLAB lays it out), then read."""

from __future__ import annotations

import numpy as np
import pytest

N = 400


def _motor(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 1e-3
    v = np.where(t >= 0.1, 6.0, 0.0)
    w = np.where(t >= 0.1, 20.0 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.1)), 0.0)
    return t, v, w + rng.normal(0, 0.02, N)


@pytest.mark.parametrize("rows", [False, True])
def test_matrix_one_signal_a_row(tmp_path, rows):
    """``data = [t; v; w]`` (3 x N, a signal a row): before, 'holds no numeric signal a motor
    log could use' (N columns taken for N signals, more than a matrix of signals has); now the
    same as the N x 3 matrix ``[t, v, w]``."""
    sio = pytest.importorskip("scipy.io")
    from pmdcid.io import parse_mapping, read_log

    t, v, w = _motor(21)
    data = np.vstack([t, v, w]) if rows else np.column_stack([t, v, w])
    p = tmp_path / "log.mat"
    sio.savemat(p, {"data": data})
    log = read_log(p, parse_mapping(["t=data[0]", "v=data[1]", "omega=data[2]"]))
    assert log.n == N and log.dt == pytest.approx(1e-3)
    np.testing.assert_array_equal(log["v"], v)
    np.testing.assert_array_equal(log["omega"], w)
