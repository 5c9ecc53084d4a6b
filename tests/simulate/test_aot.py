"""The ahead-of-time kernel (pmdcid.simulate.aot) gives the same bits as numba's JIT, is used
only when built from the current sources, and spares a command numba's import."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from pmdcid.simulate import aot, neutral_values, param_vector
from pmdcid.simulate.kernel import discretize
from pmdcid.simulate.layout import NSTATE

AHEAD = aot.load()
built = pytest.mark.skipif(AHEAD is None, reason="ahead-of-time kernel not built for these "
                           "sources (make aot; needs a C compiler)")
PAPER = {"R": 2.3724, "L": 0.0177933, "km": 0.0502, "J": 0.00310442, "bv": 0.0314,
         "bc": 0.005, "dz": 0.00635}
EFFECTS = {"fs": 0.003, "ws": 0.5, "ca": 0.001, "cn": 7.0, "bq": 1e-4, "vb": 0.2, "vmax": 1.8,
           "tau0": 0.001, "dbv": 0.002, "ke": 0.05}


LUGRE = {"sigma0": 5.0, "sigma1": 0.01}  # bristles: 1 mrad at the breakaway torque


def _vals(rng, effects) -> dict[str, float]:
    extra = {False: {}, True: EFFECTS, "lugre": LUGRE}[effects]
    vals = {**neutral_values(), **PAPER, **extra}
    for k in ("J", "bv", "bc", "dz"):
        vals[k] *= float(np.exp(0.3 * rng.standard_normal()))
    return vals


@built
@pytest.mark.parametrize("torque", [False, True])
@pytest.mark.parametrize("effects", [False, True, "lugre"])
def test_kernel_and_batch_bit_identical_to_jit(torque, effects):
    rng = np.random.default_rng(16 + 2 * torque + len(str(effects)))
    jit = aot.jit()
    t = np.arange(20000) / 1000.0
    u = (0.04 if torque else 2.0) * np.sign(np.sin(2 * np.pi * t / 4.0)) * (t % 4.0) / 4.0
    u += rng.standard_normal(len(t)) * (1e-4 if torque else 0.01)
    P, Phis, Gams = [], [], []
    for nsub in (3, 3):
        p = param_vector(_vals(rng, effects))
        Phi, Gam = discretize(p, 1e-3 / nsub, torque)
        x0 = rng.standard_normal(4) * [1.0, 1.0, 1.0, 1e-4]
        a = AHEAD.run(u, p, Phi, Gam, nsub, torque, x0)
        b = jit.run(u, p, Phi, Gam, nsub, torque, x0)
        assert np.abs(b).max() > 0
        assert a.tobytes() == b.tobytes()
        P.append(p), Phis.append(Phi), Gams.append(Gam)
    M = rng.standard_normal((6, 6)) * 30.0
    assert AHEAD.expm_small(M).tobytes() == jit.expm_small(M).tobytes()
    w = rng.standard_normal(len(t))
    th = rng.standard_normal(len(t))
    args = (u, np.array(P), np.array(Phis), np.array(Gams), 3, torque, w, th, 0.01, 0.02, 0.001,
            rng.standard_normal(4) * [1.0, 1.0, 1.0, 1e-4])
    one, two = np.empty((1, len(t), NSTATE)), np.empty((2, len(t), NSTATE))  # sets at once
    assert AHEAD.batch_cost(*args, one).tobytes() == jit.batch_cost(*args, two).tobytes()


def test_stale_or_missing_build_is_not_used(monkeypatch, tmp_path):
    stamp = tmp_path / "stamp.sha1"
    stamp.write_text("0" * 40 + "\n")  # built from other sources
    monkeypatch.setattr(aot, "STAMP", stamp)
    assert aot._load() is None
    stamp.unlink()  # never built
    assert aot._load() is None
    stamp.write_text(aot.digest() + "\n")
    monkeypatch.setenv("PMDCID_JIT", "1")  # the JIT forced
    assert aot._load() is None


def test_digest_follows_the_kernel_sources(monkeypatch):
    before = aot.digest()
    monkeypatch.setattr("pmdcid.simulate.cache.sources_hash", lambda: "edited")
    assert aot.digest() != before


def _modules_after(code: str, env: dict) -> str:
    import os

    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, **env}, check=True)
    return out.stdout.strip()


SIM = ("import sys, numpy as np; from pmdcid.simulate import simulate_values, neutral_values; "
       f"v = {{**neutral_values(), **{PAPER!r}}}; t = np.arange(2000) / 1e3; "
       "r = simulate_values(t, np.sign(np.sin(t * 6)) * 2.0, v); "
       "print(r.omega.tobytes().hex()[:4000], 'numba' in sys.modules)")


@built
def test_a_simulation_needs_no_numba_when_built_and_the_jit_agrees():
    ahead = _modules_after(SIM, {"PMDCID_JIT": ""}).split()
    jit = _modules_after(SIM, {"PMDCID_JIT": "1"}).split()
    assert ahead[1] == "False" and jit[1] == "True"
    assert ahead[0] == jit[0]
