"""fit/simfit.py: a fit's standard errors carry the uncertainty of the parameters it holds
(R and L from the blocked rotor) into the ones it fits (two-step estimator)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ident_util import step_logs

from pmdcid.fit.simfit import fit_simulation, held_uncertain
from pmdcid.model import Model
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
