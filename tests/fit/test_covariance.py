"""Standard errors under correlated residuals (pmdcid.fit.covariance), by Monte Carlo on a
linear regression whose true sampling spread is known from repetition."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import lfilter

from pmdcid.fit.covariance import (
    block_covariance,
    correlation_time,
    integrated_time,
    standard_errors,
    white_covariance,
)


@pytest.mark.parametrize(("rho", "theory"), [(0.0, 1.0), (0.9, 19.0), (0.98, 99.0)])
def test_integrated_time_of_ar1(rho, theory):
    """AR(1) with coefficient rho: tau = (1 + rho) / (1 - rho) samples (within 35 %)."""
    rng = np.random.default_rng(7)
    x = lfilter([1.0], [1.0, -rho], rng.normal(size=200_000))
    assert integrated_time(x) == pytest.approx(theory, rel=0.35)


def _monte_carlo(rho, runs, rng, n=10_000):
    t = np.linspace(0.0, 1.0, n)
    jac = np.column_stack([np.ones(n), t, np.sin(40 * t)])
    est, white_se, hac_se, infos = [], [], [], []
    for _ in range(runs):
        e = lfilter([1.0], [1.0, -rho], rng.normal(size=n))
        beta, *_ = np.linalg.lstsq(jac, e, rcond=None)
        r = e - jac @ beta
        white = np.linalg.inv(jac.T @ jac) * (r @ r) / (n - 3)
        cov, info = block_covariance(jac, r, [(0, 0, n)], white)
        est.append(beta)
        white_se.append(np.sqrt(np.diag(white)))
        hac_se.append(np.sqrt(np.diag(cov)))
        infos.append(info)
    return (np.std(est, axis=0), np.mean(white_se, axis=0), np.mean(hac_se, axis=0), infos)


def test_white_residuals_keep_the_textbook_errors():
    true_sd, white, hac, infos = _monte_carlo(0.0, 200, np.random.default_rng(1))
    assert hac == pytest.approx(white, rel=0.05)
    assert hac == pytest.approx(true_sd, rel=0.15)
    assert all(i.inflation < 1.2 and not i.lower_bound for i in infos)


def test_correlated_residuals_inflate_to_the_true_spread():
    """AR(1), rho = 0.99 (tau ~ 200 samples): the white formula understates the spread ~14x;
    the block estimate recovers most of it (batch means are biased low by a few tens of %)."""
    true_sd, white, hac, infos = _monte_carlo(0.99, 150, np.random.default_rng(2))
    assert np.all(white < 0.2 * true_sd)
    assert np.all(hac > 0.7 * true_sd) and np.all(hac < 1.3 * true_sd)
    assert np.median([i.inflation for i in infos]) > 5


def test_signals_of_one_log_share_their_blocks():
    """Two signals carrying the SAME correlated error are one piece of evidence, not two: the
    standard error must not shrink by sqrt(2) when the residual is duplicated."""
    rng = np.random.default_rng(3)
    n = 8000
    jac = np.column_stack([np.ones(n), np.linspace(0, 1, n)])
    e = lfilter([1.0], [1.0, -0.98], rng.normal(size=n))
    r = e - jac @ np.linalg.lstsq(jac, e, rcond=None)[0]
    white1 = np.linalg.inv(jac.T @ jac) * (r @ r) / n
    one, _ = block_covariance(jac, r, [(0, 0, n)], white1)
    jac2, r2 = np.vstack([jac, jac]), np.concatenate([r, r])
    white2 = np.linalg.inv(jac2.T @ jac2) * (r2 @ r2) / (2 * n)
    same, _ = block_covariance(jac2, r2, [(0, 0, n), (0, n, 2 * n)], white2)
    apart, _ = block_covariance(jac2, r2, [(0, 0, n), (1, n, 2 * n)], white2)
    assert np.sqrt(np.diag(same)) == pytest.approx(np.sqrt(np.diag(one)), rel=1e-9)
    assert np.all(np.sqrt(np.diag(apart)) < 0.8 * np.sqrt(np.diag(one)))


def test_correlation_longer_than_a_tenth_of_the_log_is_flagged():
    """A residual correlated over most of the log: blocks are capped at a tenth of it and the
    result says the standard errors are lower bounds."""
    n = 400
    jac = np.column_stack([np.ones(n), np.linspace(0, 1, n)])
    r = np.sin(np.arange(n) / 40.0)
    _, info = block_covariance(jac, r, [(0, 0, n)], np.eye(2))
    assert info.lower_bound and info.block == n // 10 and info.blocks == 10


def test_a_correlation_time_taken_first_gives_the_same_covariance(rng):
    """A long fit takes its residual's correlation time before its Jacobian exists and passes it
    in: the same covariance and info, bit for bit, as block_covariance's own. The time is the
    longest of the signal blocks', a non-finite value counting as 0."""
    n = 6000
    jac = np.column_stack([np.ones(2 * n), np.linspace(0, 1, 2 * n)])
    r = lfilter([1.0], [1.0, -0.95], rng.normal(size=2 * n))
    r[n + 17] = np.nan
    segs = [(0, 0, n), (1, n, 2 * n)]
    white = np.linalg.inv(jac.T @ jac)
    tau = correlation_time(r, segs)
    own, own_info = block_covariance(jac, r, segs, white)
    given, given_info = block_covariance(jac, r, segs, white, tau)
    assert own.tobytes() == given.tobytes() and own_info == given_info
    zeroed = np.where(np.isfinite(r), r, 0.0)
    assert tau == max(integrated_time(zeroed[a:b]) for _, a, b in segs) == own_info.tau_int


def test_too_few_blocks_fall_back_to_white():
    jac = np.column_stack([np.ones(3), np.arange(3.0)])
    white = np.eye(2)
    cov, info = block_covariance(jac, np.array([0.1, -0.2, 0.1]), [(0, 0, 3)], white)
    assert cov is white and info.blocks == 3


@pytest.mark.slow
def test_fit_nonlinear_standard_errors_match_the_spread_under_correlated_noise():
    """Round trip, 16 logs: a torque-driven staircase (60 s, 1 kHz) whose speed sensor error is
    AR(1) with a 0.4 s correlation time (150 correlation times per log). The spread of the
    estimates over the logs is the truth the reported standard errors must match (0.6-1.6x);
    the white-residual formula is more than 5x too small here."""
    from ident_util import as_log

    from pmdcid.identify.nonlinear import fit_nonlinear
    from pmdcid.model import Model
    from pmdcid.simulate import neutral_values, simulate_values
    from pmdcid.synth import PAPER, staircase

    names = ("J", "bv", "bc", "tau0")
    vals = {**neutral_values(), **PAPER, "dz": 0.0, "tau0": 5e-4}
    t = np.arange(60_000) * 1e-3
    u = staircase(t, 0.04, 1.0, np.random.default_rng(0))
    sim = simulate_values(t, u, vals, torque_driven=True)
    est, se, inflation = [], [], []
    for seed in range(16):
        rng = np.random.default_rng(100 + seed)
        e = lfilter([1.0], [1.0, -0.995], rng.normal(size=len(t)))
        e *= 0.03 * np.std(sim.omega) / np.std(e)
        res = fit_nonlinear([as_log("tau.csv", t, {"tau": u, "omega": sim.omega + e})], Model())
        est.append([res.estimates[k].value for k in names])
        se.append([res.estimates[k].stderr for k in names])
        inflation.append(res.fit.covariance.inflation)
    ratio = np.median(se, axis=0) / np.std(est, axis=0)
    for name, r in zip(names, ratio, strict=True):
        assert 0.6 < r < 1.6, (name, ratio)
    assert np.median(inflation) > 5


@settings(max_examples=40, deadline=None)
@given(c=st.floats(0.01, 100.0), s=st.floats(0.01, 100.0), seed=st.integers(0, 10_000))
def test_covariance_scales_with_the_residual_and_the_parameters(c, s, seed):
    """Units: a residual c times larger gives standard errors c times larger; a parameter
    measured in units s times smaller (its Jacobian column s times larger) has a standard
    error s times smaller; the block choice depends on neither."""
    rng = np.random.default_rng(seed)
    n = 600
    jac = np.column_stack([np.ones(n), np.linspace(0, 1, n), rng.normal(size=n)])
    r = lfilter([1.0], [1.0, -0.9], rng.normal(size=n))
    white = np.eye(3)
    cov, info = block_covariance(jac, r, [(0, 0, n)], white)
    cov_c, info_c = block_covariance(jac, c * r, [(0, 0, n)], white)
    jac_s = jac.copy()
    jac_s[:, 1] *= s
    cov_s, info_s = block_covariance(jac_s, r, [(0, 0, n)], white)
    assert info_c.block == info.block == info_s.block
    np.testing.assert_allclose(np.sqrt(np.diag(cov_c)), c * np.sqrt(np.diag(cov)), rtol=1e-8)
    se, se_s = np.sqrt(np.diag(cov)), np.sqrt(np.diag(cov_s))
    np.testing.assert_allclose(se_s[1], se[1] / s, rtol=1e-8)
    np.testing.assert_allclose(se_s[[0, 2]], se[[0, 2]], rtol=1e-8)


@pytest.mark.parametrize("seed", [0, 1])
def test_parameters_of_far_apart_sizes_keep_their_standard_errors(seed):
    """Units far apart (an input latency in s beside an inductance at its 1e-13 H floor: their
    Jacobian columns 1e12 apart) put J'J's condition number past the pseudo-inverse's cut-off;
    taken as it stood, the small direction's variance was dropped (newrigs freerun-vmeas seed
    20: a latency of 0.93 ms printed +- 1e-25 s, "4.6e+23 standard errors"). Each standard
    error is the one of the same fit in balanced units, scaled by its unit, white and
    correlated alike."""
    rng = np.random.default_rng(seed)
    n = 2000
    x = rng.normal(size=n)
    jac = np.column_stack([x + 0.3 * rng.normal(size=n), x + 0.3 * rng.normal(size=n),
                           rng.normal(size=n)])
    r = lfilter([1.0], [1.0, -0.5], rng.normal(size=n))
    units = np.array([1e6, 1e-6, 1.0])
    far = jac * units
    se = standard_errors(white_covariance(jac, r))
    se_far = standard_errors(white_covariance(far, r))
    np.testing.assert_allclose(se_far * units, se, rtol=1e-6)
    cov, _ = block_covariance(jac, r, [(0, 0, n)], np.eye(3))
    cov_far, _ = block_covariance(far, r, [(0, 0, n)], np.eye(3))
    np.testing.assert_allclose(standard_errors(cov_far) * units, standard_errors(cov), rtol=1e-6)


def test_a_variance_not_positive_is_no_standard_error():
    """A degenerate variance (zero: a dropped direction; negative: a covariance that is not
    positive semidefinite; NaN) gives NaN, never 0 (a parameter known exactly)."""
    cov = np.diag([4.0, 0.0, -1e-12, np.nan])
    cov[0, 1] = cov[1, 0] = 0.5
    se = standard_errors(cov)
    assert se[0] == 2.0
    assert np.isnan(se[1:]).all()


def test_one_variance_follows_the_same_rule():
    """The scalar sibling (a propagated g' cov g, one diagonal entry): the same rule."""
    from pmdcid.fit.covariance import standard_error

    assert standard_error(4.0) == 2.0
    for var in (0.0, -1e-12, np.nan, np.inf):
        assert np.isnan(standard_error(var)), var
