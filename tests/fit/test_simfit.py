"""fit/simfit.py: a fit's standard errors carry the uncertainty of the parameters it holds
(R and L from the blocked rotor) into the ones it fits (two-step estimator)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ident_util import step_logs

from pmdcid.fit.results import NOT_DETERMINED, format_estimates, write_estimate
from pmdcid.fit.simfit import ar_whitener, fit_simulation, held_uncertain
from pmdcid.model import Model
from pmdcid.model.params import model_from_json
from pmdcid.simulate import param_values
from pmdcid.synth import PAPER


def _model(r_stderr: float) -> Model:
    m = Model()
    for name, value in PAPER.items():
        m.set(name, value, stage="truth")
    m.set("R", PAPER["R"], r_stderr, stage="fit-electrical")
    return m


def test_held_parameters_with_a_standard_error_are_listed():
    m = _model(1e-3)
    held = held_uncertain(m, ["J", "bv"], param_values(m))
    assert held == {"R": (PAPER["R"], 1e-3)}  # km: a datasheet value without one; J, bv fitted


@pytest.mark.parametrize("rel", [2e-4, 1e-3])
def test_resistance_uncertainty_reaches_the_mechanical_parameters(rel):
    """Without back-EMF the torque per volt is km/R: an R off by e moves bv (and J, bc) by -e,
    so bv's variance gains (bv rel)^2 over the fit's own."""
    rng = np.random.default_rng(3)
    logs = step_logs(param_values(_model(0.0)), rng, amplitudes=(1.0, 2.0))
    free = ["J", "bv", "bc"]
    alone = fit_simulation(logs, _model(0.0), free, signals=("omega",))
    held = fit_simulation(logs, _model(rel * PAPER["R"]), free, signals=("omega",))
    for name in ("J", "bv"):  # bc meets the held dead zone at rest: not a pure scale
        assert held.estimates[name].value == alone.estimates[name].value  # same fit
        a, b = alone.estimates[name].stderr, held.estimates[name].stderr
        added = math.sqrt(b * b - a * a)
        assert added == pytest.approx(rel * held.estimates[name].value, rel=0.1), name


def test_a_parameter_the_logs_do_not_determine_has_no_standard_error():
    """The Stribeck velocity ws with no Stribeck effect moves nothing: its Jacobian column is
    zero and its variance is not positive. It is said in words and written as a null stderr
    (CONTRACT: the model file's stderr; the reader takes null as not known), never as 0."""
    rng = np.random.default_rng(3)
    m = _model(0.0)
    logs = step_logs(param_values(m), rng, amplitudes=(1.0, 2.0))
    res = fit_simulation(logs, m, ["J", "bv", "ws"], signals=("omega",))
    ws = res.estimates["ws"]
    assert math.isnan(ws.stderr) and ws.caveat == NOT_DETERMINED
    assert res.estimates["J"].stderr > 0 and not res.estimates["J"].caveat
    assert "±" not in str(ws) and NOT_DETERMINED in str(ws)
    line = next(x for x in format_estimates(res.estimates.values()) if x.startswith("ws"))
    assert "± 0" not in line and NOT_DETERMINED in line
    write_estimate(m, ws, "test")
    entry = m.to_json()["parameters"]["ws"]
    assert entry["stderr"] is None and entry["caveat"] == NOT_DETERMINED
    assert math.isnan(model_from_json(m.to_json()).parameters["ws"].stderr)


def _ar1(rng, n, a):
    e = rng.normal(0.0, 1.0, n)
    out = np.zeros(n)
    for k in range(1, n):
        out[k] = a * out[k - 1] + e[k]
    return out


def test_whitener_keeps_only_a_sensors_colour():
    """Fast coloured noise (AR(1) 0.5 per sample: a sensor's filter) and a slow drift (AR(1)
    0.995: the model's own error). With the slowest pole a sensor can have at 0.9: the noise
    alone keeps its pole (within 0.03 of 0.5); the drift alone is left white (up to the
    estimate's noise); the two together (the drift ten times larger) give a filter with no pole
    above 0.9, where every pole allowed gives one above 0.95 (a near-first difference)."""
    rng = np.random.default_rng(5)
    noise, drift = _ar1(rng, 20000, 0.5), 10 * _ar1(rng, 20000, 0.995) * math.sqrt(1 - 0.995**2)
    fast = ar_whitener(noise, 2, slowest=0.9)
    assert abs(max(np.roots(fast), key=abs) - 0.5) < 0.03, fast
    left = ar_whitener(drift, 2, slowest=0.9)
    assert left is None or np.max(np.abs(left[1:])) < 0.02, left  # white, up to estimation
    both = noise + drift
    assert np.max(np.abs(np.roots(ar_whitener(both, 2)))) > 0.95
    kept = ar_whitener(both, 2, slowest=0.9)
    assert kept is None or np.max(np.abs(np.roots(kept))) <= 0.9, kept


def test_a_local_stage_out_of_evaluations_is_run_on_from_where_it_stopped():
    """A fit started 30 % off with a budget of 4 evaluations stops short: run on from its end
    point (CONTINUATIONS, the default), it lowers the chi-square and counts every run's
    evaluations; with no continuation (a probe's options) it ends where the first run
    stopped."""
    from pmdcid.fit.simfit import CONTINUATIONS, FitOptions

    rng = np.random.default_rng(4)
    m = _model(0.0)
    logs = step_logs(param_values(m), rng, amplitudes=(1.0, 2.0))
    m.set("J", 1.3 * PAPER["J"])
    m.set("bv", 0.7 * PAPER["bv"])
    once = fit_simulation(logs, m, ["J", "bv"], signals=("omega",),
                          options=FitOptions(4, continuations=0))
    assert FitOptions(4).continuations == CONTINUATIONS == 2
    more = fit_simulation(logs, m, ["J", "bv"], signals=("omega",), options=FitOptions(4))
    assert not once.stats.success and once.stats.nfev <= 5
    assert more.stats.chisqr < once.stats.chisqr
    assert more.stats.nfev > once.stats.nfev
