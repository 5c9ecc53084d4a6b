"""Plausibility checks on a freshly read log (pmdcid/io/checks.py) not covered by
tests/io/test_bad_inputs.py's table."""

from __future__ import annotations

import hashlib
import shutil

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.errors import PmdcidWarning
from pmdcid.io.checks import check_angle_wrap


def _turning(rng, n: int = 3000, dt: float = 1e-3, counts: int = 4096):
    """t [s] and a measured angle [rad] (a ``counts`` encoder) of a rotor that starts from rest
    at 0.5 s and settles at 12 rad/s (several turns in the log)."""
    t = np.arange(n) * dt
    s = np.clip(t - 0.5, 0.0, None)
    theta = 12.0 * (s - 0.1 * (1.0 - np.exp(-s / 0.1)))
    q = 2 * np.pi / counts
    theta = np.round((theta + rng.normal(0.0, 0.3 * q, n)) / q) * q
    return t, theta


def test_a_wrapped_angle_is_named_where_a_turning_or_resting_one_is_not(rng):
    t, theta = _turning(rng)
    assert theta[-1] > 4 * 2 * np.pi
    assert not check_angle_wrap(theta, t, "x.csv")
    assert not check_angle_wrap(np.zeros_like(t), t, "x.csv")
    assert not check_angle_wrap(-theta, t, "x.csv")  # turning the other way
    fast = np.arange(t.size) * 3.0  # 3 rad a sample, steadily: motion, no jump
    assert not check_angle_wrap(fast, t, "x.csv")
    # the encoder's noise at rest near 0 flickers across the wrap too (0 <-> 359.9 deg)
    with pytest.warns(PmdcidWarning, match=r"theta jumps by -?6\.2\d* rad in one sample at t = "
                                           r"[\d.]+ s against its motion \(\d+ time\(s\)\): "
                                           r"a wrapped angle"):
        assert check_angle_wrap(np.mod(theta, 2 * np.pi), t, "x.csv")
    with pytest.warns(PmdcidWarning, match=r"theta jumps by -?6\.2"):
        assert check_angle_wrap(np.mod(-theta, 2 * np.pi), t, "x.csv")
    counter = np.mod(theta * 4096 / (2 * np.pi), 2**11) * 2 * np.pi / 4096  # 11 bits: half a turn
    with pytest.warns(PmdcidWarning, match=r"theta jumps by -?3\.1\d* rad"):
        assert check_angle_wrap(counter, t, "x.csv")


def test_a_stage_refuses_a_log_whose_angle_wraps(tmp_path, monkeypatch):
    """fuzz: an EV3-like log (t, v, theta) whose angle was kept within one turn was fitted by
    fit-nonlinear (exit 0, a model written with NRMSE 1.0) and refused by fit-mechanical as
    'non-positive damping ... check the speed's sign'; now every stage refuses it naming the
    wrap, the model untouched, and simulate warns."""
    rng = np.random.default_rng(3)
    t, theta = _turning(rng)
    v = np.where(t >= 0.5, 1.0, 0.0)
    rows = "\n".join(f"{a:.6f},{b:g},{c:.9g}" for a, b, c in zip(t, v, np.mod(theta, 2 * np.pi),
                                                                  strict=True))
    (tmp_path / "wrap.csv").write_text("t,v,theta\n" + rows + "\n")
    shutil.copy(FIXTURES / "paper" / "truth.json", tmp_path / "m.json")
    monkeypatch.chdir(tmp_path)
    digest = {p: hashlib.sha256((tmp_path / p).read_bytes()).hexdigest()
              for p in ("wrap.csv", "m.json")}
    for stage in ("fit-mechanical", "fit-nonlinear"):
        res = CliRunner().invoke(main, [stage, "wrap.csv", "-m", "m.json"])
        lines = [ln for ln in res.stderr.splitlines() if ln.strip()]
        assert res.exit_code == 1, res.stderr
        assert len(lines) == 1 and lines[0].startswith("error: wrap.csv: theta jumps by"), lines
        assert "a wrapped angle" in lines[0] and "--force" in lines[0]
    res = CliRunner().invoke(main, ["simulate", "wrap.csv", "-m", "m.json", "-o", "sim.csv"])
    assert res.exit_code == 0, res.stderr
    assert "warning: wrap.csv: theta jumps by" in res.stderr
    for p, h in digest.items():
        assert hashlib.sha256((tmp_path / p).read_bytes()).hexdigest() == h, p
