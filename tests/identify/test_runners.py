"""The stages as the command line runs them (:mod:`pmdcid.identify.runners`): the sequence
fit-electrical -> fit-mechanical -> fit-nonlinear on logs fit-mechanical cannot use."""

from __future__ import annotations

import numpy as np
import pytest
from ident_util import as_log

from pmdcid.errors import FitError
from pmdcid.identify.electrical import fit_electrical
from pmdcid.identify.mechanical import BY_SIMULATION, fit_mechanical
from pmdcid.identify.runners import LINEAR_START_NOTE, fit_stage, stage_nonlinear
from pmdcid.model import Model
from pmdcid.simulate import neutral_values, simulate_values

VALS = {**neutral_values(), "R": 2.0, "L": 1e-3, "km": 0.02, "ke": 0.02, "J": 1e-4,
        "bv": 2e-6, "bc": 2e-3, "dz": 1e-3}


def _staircase(seed: int) -> list:
    """Voltage staircases with current and speed at 1 kHz, each plateau 1 s: two of the
    0.5 s mechanical time constants, too short for fit-mechanical (3 needed)."""
    rng = np.random.default_rng(seed)
    t = np.arange(3200) / 1000.0
    logs = []
    for k, lev in enumerate(((6.0, 2.0, 9.0), (3.0, 8.0, 4.0))):
        u = np.select([t < 0.2, t < 1.2, t < 2.2], [0.0, lev[0], lev[1]], lev[2])
        sim = simulate_values(t, u, VALS, False)
        logs.append(as_log(f"stair{k}", t, {"v": u, "i": sim.i + rng.normal(0, 0.01, t.size),
                                            "omega": sim.omega + rng.normal(0, 0.2, t.size)}))
    return logs


def test_fit_nonlinear_starts_where_fit_mechanical_refuses():
    """fit-mechanical refuses plateaus too short to settle, pointing to fit-nonlinear; that
    stage then starts from the logs' first-order least squares, as identify does (before: the
    model lacks J, bv to start fit-nonlinear) and finds J (within 1 %) and the friction
    (bc within 15 %: it trades with bv, whose back-EMF share is 99 %)."""
    logs = _staircase(5)
    m = Model()
    fit_electrical(logs, m).apply(m)
    with pytest.raises(FitError, match="fit-nonlinear") as err:
        fit_mechanical(logs, m)
    assert BY_SIMULATION in str(err.value)
    res = fit_stage(stage_nonlinear, logs, m)
    assert LINEAR_START_NOTE in res.warnings
    e = res.estimates
    assert e["J"].value == pytest.approx(VALS["J"], rel=0.01)
    assert e["bc"].value == pytest.approx(VALS["bc"], rel=0.15)
    assert not m.has("J")  # the start went into the stage's copy only
