"""The fit engine's parameter set (pmdcid.fit.parameters) and its one problem (pmdcid.fit.problem):
bounds, fixed values and priors reach the fit; the residual is (simulated - measured) / sigma
per channel; a simulation-error fit and diagnose's refit of the same data agree."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ident_util import triangle_fit_problem

from pmdcid.errors import FitError
from pmdcid.fit.parameters import Parameters
from pmdcid.fit.problem import SWITCH_STEP, Problem, Simulation
from pmdcid.fit.simfit import FitOptions, fit_simulation
from pmdcid.model.effects import bounds_of
from pmdcid.simulate import param_values


def test_parameter_set_bounds_fixed_and_priors():
    ps = Parameters.of(["J", "bv", "bc"], {"J": 2e-3, "bv": 0.5, "bc": math.nan},
                       bounds={"bv": (0.0, 0.1)}, priors={"J": (3e-3, 1e-4), "bv": (0.1, 0.0)},
                       steps={"bc": 1e-2})
    assert (ps["J"].lower, ps["J"].upper) == bounds_of("J")
    ps.tighten("J", 1e-3, math.inf)  # never widens
    assert ps["J"].lower == 1e-3 and ps["J"].upper == bounds_of("J")[1]
    with pytest.raises(FitError, match="bc"):
        ps.start()
    full = ps.filled({"bc": 4e-3, "J": 9.0})  # only the missing value is taken
    assert full["bc"].value == 4e-3 and full["J"].value == 2e-3 and math.isnan(ps["bc"].value)
    np.testing.assert_array_equal(full.start(), [2e-3, 0.1, 4e-3])  # bv clipped to its bound
    np.testing.assert_array_equal(full.steps(), [1e-3, 1e-3, 1e-2])
    assert full.prior_rows() == [(0, 3e-3, 1e-4)]  # a zero-width prior is none
    full.fix("dz", 0.01)
    assert full.free == ["J", "bv", "bc"] and len(full.start()) == 3


def test_a_range_narrowed_to_nothing_is_a_fit_error_naming_the_parameter():
    """Limits from the logs (a Stribeck speed within the logged speeds) outside the parameter's
    physical bounds leave no room: a FitError naming it and the units to check, not scipy's
    ValueError (the CLI's internal error on a log in the wrong unit)."""
    ps = Parameters.of(["J", "ws"], {"J": 2e-3, "ws": 1.0})
    lo, hi = bounds_of("ws")
    ps.tighten("ws", 1e3 * hi, 1e6 * hi)  # never widens: lower now above upper
    with pytest.raises(FitError, match=r"no room to fit ws: .*rad/s.*units and scale"):
        ps.start()


def test_residual_is_simulated_minus_measured_over_sigma():
    truth, log, model, _ = triangle_fit_problem()
    vals = param_values(model)
    pr = Problem([log], max_samples=None, plan=["fit"], signals=("theta", "omega"),
                 sigma=[{"omega": 0.5}], simulation=Simulation())
    assert [ch.signal for ch in pr.channels] == ["theta", "omega"]
    assert pr.channels[1].sigma == 0.5
    sims = pr.simulate_all(vals)
    r = pr.weighted(sims, "all")
    assert len(r) == 2 * log.n == pr.rows("all") and pr.rows("held") == 0
    sim = sims[0]
    np.testing.assert_allclose(r[log.n:], (sim.omega - log["omega"]) / 0.5, rtol=1e-12)
    np.testing.assert_allclose(r[:log.n], (sim.theta - log["theta"]) / pr.channels[0].sigma,
                               rtol=1e-12)


def test_a_fixed_parameter_is_the_one_simulated():
    """bc held at the truth lets J and bv come back near the truth; held 40 % high, the fit
    must move them to pay for it (the fixed value reaches every simulation)."""
    truth, log, model, _ = triangle_fit_problem()
    free = ["J", "bv"]

    def fit(bc):
        ps = Parameters.of(free, {k: truth[k] * 1.15 for k in free})
        ps.fix("bc", bc)
        ps.fix("dz", truth["dz"])
        return fit_simulation([log], model, ps, ("omega",), options=FitOptions(max_nfev=60))

    right, wrong = fit(truth["bc"]), fit(1.4 * truth["bc"])
    for k in free:
        assert right.estimates[k].value == pytest.approx(truth[k], rel=0.02)
    assert wrong.stats.chisqr > 1.5 * right.stats.chisqr
    assert abs(wrong.values()["bv"] / truth["bv"] - 1) > 0.02


def test_simulation_fit_and_diagnose_refit_agree():
    """The same data, parameters, start and finite-difference steps through fit_simulation and
    through diagnose's refit (Problem.fit, its own part 'all', uncapped internal steps): the same
    minimum within 1 %, near the truth."""
    truth, log, model, free = triangle_fit_problem()
    vals = param_values(model)
    ps = Parameters.of(free, vals, steps={"bc": SWITCH_STEP, "dz": SWITCH_STEP})
    a = fit_simulation([log], model, ps, ("omega",), options=FitOptions(initial=False))
    pr = Problem([log], max_samples=None, plan=["fit"], signals=("omega",),
                 simulation=Simulation(initial=False))
    b = pr.fit(vals, free, "all", max_nfev=200)
    for k in free:
        assert b.values[k] == pytest.approx(a.values()[k], rel=0.01)
        assert a.values()[k] == pytest.approx(truth[k], rel=0.05)
    assert b.chi2["all"] == pytest.approx(a.stats.chisqr, rel=0.01)


def test_diagnose_refit_fits_a_name_given_twice_once():
    """A parameter named twice in ``free`` (a lumped model's lag free in the base and again in
    diagnose's final refits) is fitted once, as if named once; before, the engine's residual
    raised on the mismatch and the refit was reported as failed."""
    truth, log, model, free = triangle_fit_problem()
    vals = param_values(model)
    pr = Problem([log], max_samples=None, plan=["fit"], signals=("omega",),
                 simulation=Simulation(initial=False))
    once = pr.fit(vals, free, "all", max_nfev=30)
    twice = pr.fit(vals, [*free, free[0]], "all", max_nfev=30)
    assert list(twice.estimates) == list(free)
    for k in free:
        assert twice.values[k] == pytest.approx(once.values[k], rel=1e-9)


def test_a_signal_logged_exactly_constant_takes_another_logs_noise_level(rng):
    """A speed of exact zeros has no noise to measure: noise_level's floor (1e-12) would weigh
    it 1e9 times a log that moves. It takes the smallest level the same signal shows in another
    log; a signal that varies keeps its own, and with no other log the floor stays."""
    from pmdcid.fit.problem import noise_levels
    from pmdcid.io import Log

    t = np.arange(500) * 1e-3
    moving = Log("a.csv", t, {"v": np.ones(t.size), "omega": 3 + 0.01 * rng.standard_normal(500)})
    quiet = Log("b.csv", t, {"v": np.ones(t.size), "omega": 1 + 0.002 * rng.standard_normal(500)})
    still = Log("c.csv", t, {"v": np.ones(t.size), "omega": np.zeros(500)})
    levels = noise_levels([moving, quiet, still], ["omega"])
    assert levels[0]["omega"] == pytest.approx(0.01, rel=0.2)
    assert levels[1]["omega"] == pytest.approx(0.002, rel=0.2)
    assert levels[2]["omega"] == levels[1]["omega"]
    assert noise_levels([still], ["omega"])[0]["omega"] == pytest.approx(1e-12)


def test_a_fit_on_a_derived_speed_compares_it_with_the_simulation_derived_the_same_way():
    """A speed derived from an encoder's angle is compared, in a fit given its signals as in
    diagnose's own problem, with the simulated angle's speed through the same zero-phase filter
    and weighted alike. A small motor (L/R 2.5 ms, tau_m 45 ms) on a 4096-count encoder at
    1 kHz: the truth leaves a chi-square of its quantisation (0.43 a sample); compared with the
    raw simulated speed (before), the filter's rounding of the step's start left 38 a sample,
    which a fit then paid with J and the lag."""
    from pmdcid.io import Log
    from pmdcid.io.derive import derive_missing
    from pmdcid.simulate import neutral_values, simulate_values
    from pmdcid.synth import step

    vals = {**neutral_values(), "R": 2.0, "km": 0.02, "ke": 0.02, "L": 0.005,
            "bv": 0.0002 / 9, "J": 0.01 * 0.0009, "bc": 0.003, "dz": 0.0036}
    t = np.arange(1500) * 1e-3
    u = step(t, 6.0, 0.2)
    q = 2 * np.pi / 4096
    theta = np.round(simulate_values(t, u, vals, nsub=64).theta / q) * q
    log = Log(path="enc.csv", t=t, data={"v": u, "theta": theta}, meta={})
    derive_missing(log)
    prob = Problem([log], max_samples=None, plan=["fit"], signals=("omega",))
    fit_ch, = prob.channels
    judged, = Problem([log], max_samples=None, plan=["fit"]).channels
    assert fit_ch.derived_cutoff == judged.derived_cutoff is not None
    assert fit_ch.sigma == judged.sigma
    n = prob.count("fit")
    assert prob.chi2(vals)["fit"] < 2.0 * n
    fit_ch.derived_cutoff = None  # the raw simulated speed: the comparison matters here
    assert prob.chi2(vals)["fit"] > 10.0 * n
