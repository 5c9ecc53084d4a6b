"""The step fits' numpy filters give what scipy.signal's give (identify/filters.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pmdcid.identify.filters import correlate_valid, medfilt5, savgol


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.integers(5, 400), st.integers(2, 30), st.integers(0, 1),
       st.floats(1e-5, 1.0))
def test_savgol_is_scipys_interp_mode(seed, n, half, deriv, delta):
    from scipy.signal import savgol_filter

    w = min(2 * half + 1, n - (1 - n % 2))
    if w < 3:
        return
    y = np.cumsum(np.random.default_rng(seed).normal(size=n)) + 100.0
    want = savgol_filter(y, w, 2, deriv=deriv, delta=delta, mode="interp")
    got = savgol(y, w, 2, deriv=deriv, delta=delta)
    assert np.max(np.abs(got - want)) <= 1e-9 * max(np.max(np.abs(want)), 1e-300)


@pytest.mark.parametrize("n", [5, 6, 50, 1001])
def test_medfilt5_is_scipys(n, rng):
    from scipy.signal import medfilt

    y = rng.normal(size=n)
    y[n // 2] = 1e6  # a spike
    assert np.array_equal(medfilt5(y), medfilt(y, 5))


@pytest.mark.parametrize("n, m", [(10, 10), (100, 37), (4097, 4000), (3, 1)])
def test_correlate_valid_is_scipys(n, m, rng):
    from scipy.signal import correlate

    a, v = rng.normal(size=n), rng.normal(size=m)
    want = correlate(a, v, mode="valid", method="direct")
    assert np.allclose(correlate_valid(a, v), want, rtol=0, atol=1e-10 * np.sum(np.abs(v)))
