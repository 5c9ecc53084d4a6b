"""The stick-slip loop compiled twice (issue #16): without the friction curve and its
positivity hold when the model cannot need them, with them otherwise; both give the same states."""

import numpy as np
import pytest

from pmdcid.simulate import param_vector, simulate_values
from pmdcid.simulate.terms import friction_guarded
from pmdcid.synth import staircase, triangle

#: the friction curve switched on with every value 0: the guarded loop, the same friction
ZERO_CURVE = {"fcw1": 0.5, "fcw2": 2.0, "fcw3": 5.0, "fcw4": 20.0, "fc1": 0.0, "fc2": 0.0,
              "fc3": 0.0}


def _guarded(vals) -> bool:
    return bool(friction_guarded.py_func(param_vector(vals)))


def test_plain_model_takes_the_unguarded_loop(paper_values):
    assert not _guarded(paper_values)
    assert not _guarded({**paper_values, "fs": 3e-3, "ws": 0.15, "bq": 1e-7})


@pytest.mark.parametrize("extra", [{"fcw4": 20.0}, {"bq": -1e-7}, {"dbv": 1e-4}, {"bc": -1e-3},
                                   {"fs": -1e-3}, {"bv": -1e-4}])
def test_terms_that_can_act_take_the_guarded_loop(paper_values, extra):
    assert _guarded({**paper_values, **extra})


@pytest.mark.parametrize("extra", [{}, {"fs": 3e-3, "ws": 0.15}, {"ca": 1e-3, "cn": 7.0}])
def test_both_loops_give_the_same_states(paper_values, extra, rng):
    vals = {**paper_values, **extra}
    t = np.arange(30000) * 1e-3
    v = triangle(t, 2.0, 10.0) + staircase(t, 0.3, 0.7, rng)
    assert _guarded({**vals, **ZERO_CURVE}) and not _guarded(vals)
    plain = simulate_values(t, v, vals, nsub=3)
    guarded = simulate_values(t, v, {**vals, **ZERO_CURVE}, nsub=3)
    assert np.count_nonzero(plain.omega == 0.0) > 100  # stick-slip was exercised
    for s in ("i", "omega", "theta"):
        np.testing.assert_array_equal(plain.get(s), guarded.get(s))


# the test's own speeds reach 1e300: r*r overflows to inf there (exp(-inf) = 0, the point)
@pytest.mark.filterwarnings("ignore:overflow encountered in scalar multiply:RuntimeWarning")
def test_stribeck_skips_only_an_exponential_that_is_exactly_zero(paper_values):
    """stribeck_excess skips exp(-(omega/ws)^2) past EXP_ZERO (glibc's slow underflow path):
    the same bits as the plain formula at every speed, the cut-off region included."""
    import math

    from pmdcid.simulate.terms import EXP_ZERO, stribeck_excess

    ws, fs = 0.15, 3e-3
    p = param_vector({**paper_values, "fs": fs, "ws": ws})
    edge = math.sqrt(EXP_ZERO) * ws
    speeds = np.concatenate([np.linspace(0.0, 2 * edge, 4001),
                             edge * (1 + np.arange(-50, 50) * 1e-6), [1e3, 1e300, np.inf]])
    for w in np.concatenate([speeds, -speeds]):
        r = w / ws
        assert stribeck_excess.py_func(p, w) == fs * math.exp(-r * r)
    assert math.isnan(stribeck_excess.py_func(p, math.nan))
    assert stribeck_excess.py_func(param_vector({**paper_values, "fs": 0.0}), 0.1) == 0.0
