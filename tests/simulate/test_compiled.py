"""The compiled kernel (pmdcid.simulate.compiled: the C generated from the kernel's source, built
by setup.py) gives numba's numbers, is used only when built from the current sources, and spares
a command numba's import.

Tolerance: 1e-12 of each output's largest magnitude. Both compile the same operations without
fast-math or fused multiply-adds and call the same libm: on x86-64 with gcc they agree to the
bit on every case here; the tolerance leaves room for another compiler's or platform's libm."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from pmdcid.identify import grid
from pmdcid.simulate import compiled, kernel, neutral_values, param_vector
from pmdcid.simulate.kernel import discretize
from pmdcid.simulate.layout import NSTATE
from pmdcid.simulate.lazyjit import real

FAST = compiled.load()
built = pytest.mark.skipif(FAST is None, reason="compiled kernel not built for these sources "
                           "(pip install . or python setup.py build_ext --inplace; needs a C "
                           "compiler)")
TOL = 1e-12
PAPER = {"R": 2.3724, "L": 0.0177933, "km": 0.0502, "J": 0.00310442, "bv": 0.0314,
         "bc": 0.005, "dz": 0.00635}
EFFECTS = {"fs": 0.003, "ws": 0.5, "ca": 0.001, "cn": 7.0, "bq": 1e-4, "vb": 0.2, "vmax": 1.8,
           "tau0": 0.001, "dbv": 0.002, "ke": 0.05, "fcw1": 0.1, "fcw2": 0.3, "fcw3": 0.6,
           "fcw4": 1.0, "fc1": 0.002, "fc2": 0.003, "fc3": 0.0015}
LUGRE = {"sigma0": 5.0, "sigma1": 0.01}  # bristles: 1 mrad at the breakaway torque


def _vals(rng, effects) -> dict[str, float]:
    extra = {False: {}, True: EFFECTS, "lugre": LUGRE}[effects]
    vals = {**neutral_values(), **PAPER, **extra}
    for k in ("J", "bv", "bc", "dz"):
        vals[k] *= float(np.exp(0.3 * rng.standard_normal()))
    return vals


def close(a, b) -> bool:
    return bool(np.all(np.abs(a - b) <= TOL * np.max(np.abs(b), axis=0)))


@built
@pytest.mark.parametrize("torque", [False, True])
@pytest.mark.parametrize("effects", [False, True, "lugre"])
def test_kernel_discretisation_and_batch_match_the_jit(torque, effects):
    rng = np.random.default_rng(16 + 2 * torque + len(str(effects)))
    t = np.arange(20000) / 1000.0
    u = (0.04 if torque else 2.0) * np.sign(np.sin(2 * np.pi * t / 4.0)) * (t % 4.0) / 4.0
    u += rng.standard_normal(len(t)) * (1e-4 if torque else 0.01)
    P, Phis, Gams = [], [], []
    for _ in range(2):
        p = param_vector(_vals(rng, effects))
        Phi, Gam = np.empty((4, 3, 3)), np.empty((4, 3, 3))
        real(kernel.discretize_into)(p, 1e-3 / 3, torque, Phi, Gam)
        Phi_c, Gam_c = np.empty((4, 3, 3)), np.empty((4, 3, 3))
        FAST.discretize_into(p, 1e-3 / 3, torque, Phi_c, Gam_c)
        assert close(Phi_c, Phi) and close(Gam_c, Gam)
        x0 = rng.standard_normal(4) * [1.0, 1.0, 1.0, 1e-4]
        a = FAST.run(u, p, Phi, Gam, 3, torque, x0)
        b = real(kernel._run)(u, p, Phi, Gam, 3, torque, x0)
        assert np.abs(b).max() > 0 and close(a, b)
        P.append(p), Phis.append(Phi), Gams.append(Gam)
    w = rng.standard_normal(len(t))
    th = rng.standard_normal(len(t))
    args = (u, np.array(P), np.array(Phis), np.array(Gams), 3, torque, w, th, 0.01, 0.02, 0.001,
            rng.standard_normal((2, 4)) * [1.0, 1.0, 1.0, 1e-4])  # each set's own start
    one, two = np.empty((1, len(t), NSTATE)), np.empty((2, len(t), NSTATE))  # sets at once
    assert close(FAST.batch_cost(*args, one), real(grid._batch_cost)(*args, two))


@built
def test_arrays_the_c_cannot_read_are_refused():
    p = param_vector({**neutral_values(), **PAPER})
    Phi, Gam = discretize(p, 1e-3, False)
    x0 = np.zeros(4)
    with pytest.raises(ValueError, match="contiguous float64"):
        FAST.run(np.ones(10, np.float32), p, Phi, Gam, 1, False, x0)
    with pytest.raises(ValueError, match="contiguous float64"):
        FAST.run(np.ones(20)[::2], p, Phi, Gam, 1, False, x0)
    with pytest.raises(ValueError, match="shape"):
        FAST.run(np.ones(10), p[:-1], Phi, Gam, 1, False, x0)


def test_stale_or_missing_build_is_not_used(monkeypatch, tmp_path):
    if FAST is not None:
        monkeypatch.setattr("pmdcid.simulate.cache.sources_hash", lambda: "edited")
        assert compiled._load() is None  # built from other sources
        monkeypatch.undo()
    monkeypatch.setattr(compiled, "HERE", tmp_path)  # never built
    assert compiled.library_path() is None and compiled._load() is None
    monkeypatch.undo()
    monkeypatch.setenv("PMDCID_JIT", "1")  # the JIT forced
    assert compiled._load() is None


SIM = ("import sys, numpy as np; from pmdcid.simulate import simulate_values, neutral_values; "
       f"v = {{**neutral_values(), **{PAPER!r}}}; t = np.arange(2000) / 1e3; "
       "r = simulate_values(t, np.sign(np.sin(t * 6)) * 2.0, v); "
       "np.save(sys.argv[1], r.omega); print('numba' in sys.modules)")


@built
def test_a_simulation_needs_no_numba_when_built_and_the_jit_agrees(tmp_path):
    def run(env, name):
        out = subprocess.run([sys.executable, "-c", SIM, str(tmp_path / name)],
                             capture_output=True, text=True, check=True,
                             env={**os.environ, **env})
        return out.stdout.strip(), np.load(tmp_path / name)

    (numba_c, c), (numba_jit, jit) = run({"PMDCID_JIT": ""}, "c.npy"), run({"PMDCID_JIT": "1"},
                                                                          "jit.npy")
    assert numba_c == "False" and numba_jit == "True"
    assert close(c, jit)
