"""The one solver (pmdcid/fit/solver.py): what it turns into a FitError and what it lets through.

A residual that raises is a bug (or the model's own PmdcidError) and must reach the caller as
raised: before, every ValueError inside a residual became "... failed" and identify and
diagnose skipped a stage silently (a names/values mismatch surfaced only as a skipped diagnose).
"""

import numpy as np
import pytest

from pmdcid.errors import FitError, ModelError
from pmdcid.fit.solver import solve


def _line_fit(resid):
    """A two-parameter least-squares fit through :func:`solve` with residual ``resid``."""
    z0 = np.array([0.5, 0.5])
    return solve(resid, z0, np.full(2, -10.0), np.full(2, 10.0), scale=np.ones(2),
                 what="line fit")


def _line_data(rng):
    t = np.linspace(0.0, 1.0, 50)
    return t, 2.0 * t + 1.0 + 0.01 * rng.standard_normal(t.size)


def test_solve_fits_a_line():
    t, y = _line_data(np.random.default_rng(1))
    sol = _line_fit(lambda z: z[0] * t + z[1] - y)
    assert sol.x == pytest.approx([2.0, 1.0], abs=0.02)


@pytest.mark.parametrize("exc", [ValueError("names zipped against a shorter vector"),
                                 IndexError("index 3 is out of bounds")])
@pytest.mark.parametrize("when", [0, 1, 5])  # at the start, in the first Jacobian, later
def test_a_bug_in_the_residual_propagates_as_raised(exc, when):
    t, y = _line_data(np.random.default_rng(2))
    calls = [0]

    def resid(z):
        calls[0] += 1
        if calls[0] > when:
            raise exc
        return z[0] * t + z[1] - y

    with pytest.raises(type(exc), match=str(exc)):
        _line_fit(resid)


def test_the_models_own_error_passes_through():
    def resid(z):
        raise ModelError("parameter 'J' out of range")

    with pytest.raises(ModelError, match="'J' out of range"):
        _line_fit(resid)


def test_a_residual_not_finite_at_the_start_is_a_fit_error():
    t, y = _line_data(np.random.default_rng(3))

    def resid(z):
        return np.where(t > 0.5, np.inf, z[0] * t + z[1] - y)

    with pytest.raises(FitError, match="line fit failed: the residual is not finite"):
        _line_fit(resid)


def test_a_residual_not_finite_later_only_shrinks_the_step():
    """A trial point whose residual is not finite is a rejected step, not an error: the 4th
    evaluation (the first trial point, after the start and two Jacobian columns) is NaN."""
    t, y = _line_data(np.random.default_rng(4))
    calls = [0]

    def resid(z):
        calls[0] += 1
        r = z[0] * t + z[1] - y
        return np.full_like(r, np.nan) if calls[0] == 4 else r

    sol = _line_fit(resid)
    assert calls[0] > 4
    assert sol.x == pytest.approx([2.0, 1.0], abs=0.02)


@pytest.mark.parametrize("lo, hi", [(np.array([-10.0, 2.0]), np.array([10.0, 1.0])),
                                    (np.array([-10.0, 1.0]), np.array([10.0, 1.0]))])
def test_bounds_that_leave_no_room_are_a_fit_error_not_scipys_value_error(lo, hi):
    """scipy refuses lower >= upper with a bare ValueError, which reached the CLI edge as an
    internal error (diagnose on a log whose speed scale put Stribeck's ws range beyond its
    physical bound); the engine names the fit instead."""
    t, y = _line_data(np.random.default_rng(4))
    with pytest.raises(FitError, match="line fit failed: parameter 2 has no room"):
        solve(lambda z: z[0] * t + z[1] - y, np.array([0.5, 0.5]), lo, hi, scale=np.ones(2),
              what="line fit")
