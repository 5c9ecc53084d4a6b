"""The screen's joint step (pmdcid/diagnose/screen.py): the base parameters' linearised moves
start a refit only where the refit may start (fit/problem.py's refit_range)."""

import pytest

from pmdcid.diagnose.screen import feasible_step
from pmdcid.fit.problem import BASE_RANGE, refit_range


def test_a_step_beyond_the_range_is_shortened_as_a_whole():
    """test_back_emf_found_on_logs_with_current's back_emf screen: R 38 -> -290 ohm, L x33.
    The start was a negative resistance (a growing current, the residual overflowing); now the
    step stops where R reaches R/30, L moving by the same fraction of its move."""
    vals = {"R": 38.0, "L": 1.08e-3, "J": 1e-5}
    target = {"R": -290.7, "L": 3.52e-2, "J": 1.1e-5}
    got = feasible_step(vals, target)
    frac = (38.0 / BASE_RANGE - 38.0) / (-290.7 - 38.0)
    assert got["R"] == pytest.approx(38.0 / BASE_RANGE)
    assert got["L"] == pytest.approx(1.08e-3 + frac * (3.52e-2 - 1.08e-3))
    assert got["J"] == pytest.approx(1e-5 + frac * 1e-6)
    for p, x in got.items():
        lo, hi = refit_range(p, vals[p])
        assert lo <= x <= hi


def test_a_step_within_the_range_is_kept_and_a_parameter_at_its_bound_held():
    vals = {"R": 2.0, "bv": 1e-3, "bc": 0.0}
    got = feasible_step(vals, {"R": 2.5, "bv": 0.8e-3, "bc": -1e-3})
    assert got == {"R": 2.5, "bv": pytest.approx(0.8e-3), "bc": 0.0}
