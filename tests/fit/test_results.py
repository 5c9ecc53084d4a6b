"""fit/results.py: the NRMSE where it is undefined, and how a table says so."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdcid.fit.results import (
    NRMSE_UNDEFINED,
    Estimate,
    FitStats,
    SimFitResult,
    correlations,
    nrmse,
    nrmse_text,
)


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


def test_correlations_of_a_covariance_that_is_not_psd():
    """A degenerate third column (its variance a rounding's 1e-30, its covariances with the
    others of the others' size, as a non-PSD sum leaves them): its raw correlations are ~1e7;
    :func:`correlations` gives it a NaN row and keeps the determined pair exactly."""
    sd = np.array([2.0, 0.5])
    r01 = -0.6
    cov = np.array([[sd[0] ** 2, r01 * sd[0] * sd[1], 0.9],
                    [r01 * sd[0] * sd[1], sd[1] ** 2, -0.2],
                    [0.9, -0.2, 1e-30]])
    r = correlations(cov)
    assert r[0, 1] == pytest.approx(r01) and r[1, 0] == pytest.approx(r01)
    assert np.isnan(r[2]).all() and np.isnan(r[:, 2]).all()
    assert np.nanmax(np.abs(r)) <= 1.0


def test_correlations_zero_or_negative_variance_and_rounding():
    """A zero and a negative variance are degenerate (NaN rows); 1 + 1e-12 is rounding, clipped."""
    cov = np.array([[1.0, 1.0 + 1e-12, 0.3, 0.1], [1.0 + 1e-12, 1.0, 0.2, 0.1],
                    [0.3, 0.2, 0.0, 0.0], [0.1, 0.1, 0.0, -1e-8]])
    r = correlations(cov)
    assert r[0, 1] == 1.0 and r[0, 0] == 1.0
    assert np.isnan(r[2]).all() and np.isnan(r[3]).all()


def test_sim_fit_result_correl_within_unit_interval():
    """A result built with a correlation of 9 (a non-PSD covariance's) says NaN, not 9."""
    est = {n: Estimate(n, 1.0, 0.1, "") for n in ("J", "bc")}
    stats = FitStats(100, 2, 98.0, 5, True, "")
    res = SimFitResult(est, stats, {"J": {"bc": 9.0}, "bc": {"J": -0.5}})
    assert math.isnan(res.correlation("J", "bc")) and res.correlation("bc", "J") == -0.5


def test_fitted_writes_a_bounded_error_spanning_its_range_in_words():
    """A share fitted 1e-4 ± 0.58 (its +-2 se cover [0, 1]): no standard error, the words;
    the table says it without a ±."""
    from pmdcid.fit.results import fitted, format_estimates

    e = fitted("ke_share", 1e-4, 0.58, "1")
    assert math.isnan(e.stderr) and "bounded only by its range [0, 1]" in e.caveat
    assert "±" not in str(e)
    line = format_estimates([e])[1]
    assert "0.58" not in line and "bounded only by its range" in line
    assert fitted("ke_share", 0.9, 0.2, "1").stderr == 0.2
    assert fitted("tau_e", 0.002, 0.6, "s").caveat.startswith("not determined by these logs")


def test_honest_reads_a_widened_error_again():
    import dataclasses

    from pmdcid.fit.results import fitted, honest

    e = fitted("ke_share", 0.9, 0.01, "1", caveat="a note")
    wide = honest(dataclasses.replace(e, stderr=0.6))
    assert math.isnan(wide.stderr) and wide.caveat.endswith("; a note")
    back = honest(dataclasses.replace(wide, stderr=0.05))  # a narrower reading: words dropped
    assert back.stderr == 0.05 and back.caveat == "a note"
