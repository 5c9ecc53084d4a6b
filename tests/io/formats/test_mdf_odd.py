"""MDF files as a test bench writes them, beyond one group of uniquely named channels: each
written with asammdf, then read."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pmdcid.cli import main

N = 400


def _motor(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 1e-3
    v = np.where(t >= 0.1, 6.0, 0.0)
    w = np.where(t >= 0.1, 20.0 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.1)), 0.0)
    return t, v, w + rng.normal(0, 0.02, N)


def test_unique_channel_named_by_its_group(tmp_path):
    """docs/io.md: '-c omega=motor/n_mot names the same channel by its group'. Before, that
    mapping (with or without a scale) was a usage error, exit 2: "'n_mot' is neither a number
    nor a unit"; now it reads the channel, its scale applied."""
    asammdf = pytest.importorskip("asammdf")
    from pmdcid.io import parse_mapping, read_log

    t, v, w = _motor(11)
    p = tmp_path / "bench.mf4"
    m = asammdf.MDF(version="4.10")
    m.append([asammdf.Signal(v, t, name="u_arm"),
              asammdf.Signal(w * 60 / (2 * np.pi), t, name="n_mot")], acq_name="motor")
    m.save(p, overwrite=True)
    m.close()
    log = read_log(p, parse_mapping(["v=motor/u_arm", "omega=motor/n_mot*rpm"]))
    np.testing.assert_allclose(log["omega"], w, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(log["v"], v)
    res = CliRunner().invoke(main, ["simulate", str(p), "-m", str(tmp_path / "m.json"), "-o",
                                    str(tmp_path / "s.csv"), "-c", "v=u_arm", "-c",
                                    "omega=-motor/n_mot*rpm"])
    assert res.exit_code == 1, res.output  # the model file is missing: past the mapping
    assert "no such model file" in res.stderr, res.stderr
