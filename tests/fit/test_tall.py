"""Tall least-squares problems compressed before the solver (pmdcid.fit.tall) give the
uncompressed answer to rounding: the R factor, a smooth toy problem and a whole
simulation-error fit (compression forced on a log of ordinary length)."""

from __future__ import annotations

import numpy as np
import pytest
from ident_util import triangle_fit_problem

import pmdcid.fit.tall as tall
from pmdcid.fit.simfit import FitOptions, fit_simulation
from pmdcid.fit.solver import solve


def test_compressed_jacobian_keeps_the_normal_equations():
    rng = np.random.default_rng(7)
    m, n = 10_001, 4
    J = rng.normal(size=(m, n)) * np.array([1.0, 1e-3, 1e3, 5.0])
    J[:, 1] *= 0.0  # a zero column (an event no step crossed): rank deficient
    f = rng.normal(size=m) + J @ np.array([0.3, -2.0, 1e-3, 0.1])
    Jc = tall.compressed_jacobian(f, J.T.copy())
    fc = np.zeros(n + 1)
    fc[0] = np.linalg.norm(f)
    assert Jc.shape == (n + 1, n)
    np.testing.assert_allclose(Jc.T @ Jc, J.T @ J, rtol=0, atol=1e-13 * np.abs(J.T @ J).max())
    np.testing.assert_allclose(Jc.T @ fc, J.T @ f, rtol=0, atol=1e-13 * np.abs(J.T @ f).max())


def _toy(z, out=None):
    t = np.linspace(0.0, 4.0, 40_001)
    f = z[0] * np.exp(-z[1] * t) + z[2] * np.sin(3.0 * t) - (2.0 * np.exp(-0.7 * t) + 0.1)
    if out is None:
        return f
    out[:] = f
    return out


def test_toy_problem_same_answer_as_uncompressed():
    lo, hi = np.array([0.0, 0.0, -1.0]), np.array([5.0, 5.0, 1.0])
    z0 = np.array([1.0, 1.5, 0.3])
    ref = solve(_toy, z0, lo, hi, scale=np.ones(3), fills=True)
    ours = solve(_toy, z0, lo, hi, scale=np.ones(3), fills=True, rows=tall.TALL_ROWS)
    assert ref.jac.shape == ours.jac.shape == (40_001, 3)
    np.testing.assert_allclose(ours.z, ref.z, rtol=1e-9)
    np.testing.assert_allclose(ours.fun, ref.fun, rtol=0, atol=1e-9 * np.abs(ref.fun).max())
    np.testing.assert_allclose(ours.jac, ref.jac, rtol=0, atol=1e-7 * np.abs(ref.jac).max())
    assert ours.fun.tobytes() == _toy(ours.z).tobytes()  # the full residual at the solution


def test_simulation_fit_same_answer_as_uncompressed(monkeypatch):
    truth, log, model, free = triangle_fit_problem()

    def fit():
        return fit_simulation([log], model, free, signals=("omega", "theta"),
                          options=FitOptions(max_nfev=30))

    ref = fit()
    monkeypatch.setattr(tall, "TALL_ROWS", 1)
    ours = fit()
    for n in free:
        assert ours.estimates[n].value == pytest.approx(ref.estimates[n].value, rel=1e-9)
        assert ours.estimates[n].stderr == pytest.approx(ref.estimates[n].stderr, rel=1e-6)
        assert ours.estimates[n].value == pytest.approx(truth[n], rel=0.05)
    assert ours.stats.chisqr == pytest.approx(ref.stats.chisqr, rel=1e-9)
