"""fit/results.py: the NRMSE where it is undefined, and how a table says so."""

from __future__ import annotations

import math

import numpy as np

from pmdcid.fit.results import NRMSE_UNDEFINED, nrmse, nrmse_text


def test_nrmse_of_a_measurement_that_never_changes_is_undefined(rng):
    """A speed logged as exact zeros (a stalled or unplugged sensor): std 0, so RMS/std has no
    value; NaN, and a table says it in words, never ``inf``."""
    sim = rng.normal(0.0, 0.1, 500)
    value = nrmse(sim, np.zeros(500))
    assert math.isnan(value)
    assert nrmse_text(value) == NRMSE_UNDEFINED
    assert "inf" not in nrmse_text(math.inf) and "nan" not in nrmse_text(value)


def test_nrmse_text_of_a_number(rng):
    meas = rng.normal(0.0, 1.0, 2000)
    value = nrmse(meas + rng.normal(0.0, 0.1, 2000), meas)
    assert 0.08 < value < 0.12
    assert nrmse_text(value) == f"{value:.4f}"
