"""The fits' preallocated forward-difference Jacobian (pmdcid.fit.fdjac) gives bit for bit
what scipy's jac="2-point" gives: the Jacobian itself, at and away from bounds, and whole fits."""

from __future__ import annotations

import numpy as np
import pytest
from ident_util import triangle_fit_problem
from scipy.optimize._numdiff import approx_derivative

import pmdcid.fit.fdjac as fdjac
import pmdcid.runtime.cpus as cpus
from pmdcid.fit.fdjac import ForwardJacobian
from pmdcid.fit.simfit import FitOptions, fit_simulation


def _toy(x, out=None):
    t = np.linspace(0.0, 3.0, 5001)
    f = np.sin(x[0] * t) * np.exp(-x[1] * t) + x[2] * t**2 - np.cbrt(x[3] + t)
    if out is None:
        return f
    out[:] = f
    return out


@pytest.mark.parametrize("where", ["inside", "at upper bounds", "at lower bounds"])
def test_jacobian_bit_identical_to_scipy_2_point(where):
    lb = np.array([0.5, 0.0, -1.0, -2.0])
    ub = np.array([3.0, 2.0, 1.0, 2.0])
    x = {"inside": np.array([1.3, 0.7, 0.2, -0.3]), "at upper bounds": ub.copy(),
         "at lower bounds": lb.copy()}[where]
    for rel in (1e-3, np.array([1e-3, 1e-2, 1e-4, 1e-3])):
        fd = ForwardJacobian(_toy, rel, lb, ub)
        f0 = fd.fun(x)
        ours = fd(x.copy())
        ref = approx_derivative(_toy, x, method="2-point", rel_step=rel, f0=f0, bounds=(lb, ub))
        assert np.abs(ref).max() > 0
        assert ours.shape == ref.shape and ours.flags.f_contiguous == ref.flags.f_contiguous
        assert ours.tobytes(order="A") == ref.tobytes(order="A")


def _fit(log, model, free):
    return fit_simulation([log], model, free, signals=("omega", "theta"),
                          options=FitOptions(max_nfev=30))


def test_fit_bit_identical_to_scipy_2_point_and_recovers_truth(monkeypatch):
    truth, log, model, free = triangle_fit_problem()
    ours = _fit(log, model, free)
    monkeypatch.setattr(fdjac, "_compute_absolute_step", None)  # scipy's own "2-point"
    assert ForwardJacobian(None, 1e-3, [0], [1]).jac == "2-point"
    ref = _fit(log, model, free)
    for n in free:
        assert ours.estimates[n].value == ref.estimates[n].value
        assert ours.estimates[n].stderr == ref.estimates[n].stderr
        assert ours.estimates[n].value == pytest.approx(truth[n], rel=0.05)
    assert ours.stats.nfev == ref.stats.nfev


def _kernel_resid(paper):
    """A residual that simulates (the compiled kernel, run from the pool's threads)."""
    from pmdcid.simulate import simulate_values
    from pmdcid.synth import triangle

    t = np.arange(6000) * 1e-3
    u = triangle(t, 2.0, 3.0)
    names = ("J", "bv", "bc", "dz")
    base = simulate_values(t, u, paper).omega

    def resid(x, out=None):
        sim = simulate_values(t, u, {**paper, **dict(zip(names, x, strict=True))}).omega
        f = sim - base + 0.01
        if out is None:
            return f
        out[:] = f
        return out

    return resid, np.array([paper[n] for n in names]) * 1.1


@pytest.mark.parametrize("fills", [False, True])
def test_parallel_columns_bit_identical_to_serial(monkeypatch, paper_values, fills):
    resid, x = _kernel_resid(paper_values)
    lb, ub = np.zeros(4), x * 10
    serial = ForwardJacobian(resid, 1e-2, lb, ub, fills=fills)(x.copy()).copy()
    monkeypatch.setattr(cpus, "workers", lambda: 2)  # threads even on a 1-CPU machine
    par = ForwardJacobian(resid, 1e-2, lb, ub, fills=fills, parallel=True)(x.copy())
    assert np.abs(serial).max() > 0
    assert par.tobytes(order="F") == serial.tobytes(order="F")


def test_error_in_a_column_reaches_the_caller(monkeypatch):
    monkeypatch.setattr(cpus, "workers", lambda: 2)

    def resid(x):
        if x[1] != 1.0:
            raise ValueError("column 1 failed")
        return np.ones(3) * x.sum()

    fd = ForwardJacobian(resid, 1e-3, [-5, -5, -5], [5, 5, 5], parallel=True)
    with pytest.raises(ValueError, match="column 1 failed"):
        fd(np.array([1.0, 1.0, 1.0]))
