"""A km written as ke (no datasheet) follows a refitted ke (identify/freerun.py, follow_ke).

Found by issue 24's new-user checks: a motor with a brush drop and current logged, identified
without --km (km = ke from the free-running fit, biased by the drop), then diagnose added
brush_drop and refitted ke 0.0539 -> 0.0500 but left km at 0.0539: J, bv, bc came out 8 %
high at a thousand standard errors. Round trip: the torque-equation parameters scale with km,
so the model simulates exactly as before, and a datasheet km is never touched.
"""

from __future__ import annotations

import numpy as np
import pytest

from pmdcid.identify.freerun import KM_FROM_KE, follow_ke
from pmdcid.simulate import param_values, simulate_values
from pmdcid.synth import truth_model

TRUE = {"R": 2.0, "L": 4e-3, "km": 0.05, "ke": 0.05, "J": 1.25e-4, "bv": 2e-6, "bc": 2e-3,
        "dz": 1e-3}


def _fitted(km_stage):
    """The model a refit leaves: ke at the truth, km at the old (8 % high) ke, and the torque
    parameters as the refit found them (only their ratio to km is seen): 8 % high too."""
    m = truth_model({k: v * (1.0786 if k in ("km", "J", "bv", "bc", "dz") else 1.0)
                     for k, v in TRUE.items()}, ["back_emf"])
    m.set("km", m.value("km"), 7.8e-4, "N m/A", stage=km_stage)
    m.set("J", m.value("J"), 1e-8, "kg m^2", stage="diagnose")
    dz = m.parameters.pop("dz").value
    m.set_bounded("dz", 0.0, 2 * dz, dz)
    return m


def _run(m, rng):
    t = np.arange(2000) * 1e-3
    u = np.where(t > 0.2, 6.0, 0.5) + rng.normal(0.0, 0.5, t.size)
    sim = simulate_values(t, u, param_values(m))
    return np.column_stack([sim.i, sim.omega])


def test_km_from_ke_follows_a_refitted_ke_and_the_model_simulates_the_same():
    m = _fitted(KM_FROM_KE)
    before = _run(m, np.random.default_rng(3))
    km_before = m.value("km")
    follow_ke(m, km_before)
    assert m.value("km") == m.value("ke") == pytest.approx(0.05, rel=1e-12)
    for k in ("J", "bv", "bc"):
        assert m.value(k) == pytest.approx(TRUE[k], rel=1e-3), k
    assert m.parameters["J"].stderr == pytest.approx(1e-8 * 0.05 / km_before, rel=1e-12)
    assert m.parameters["dz"].interval[1] == pytest.approx(2 * TRUE["dz"], rel=1e-3)
    assert m.value("R") == TRUE["R"] and m.value("L") == TRUE["L"]
    np.testing.assert_allclose(_run(m, np.random.default_rng(3)), before, rtol=1e-9, atol=1e-9)


def test_a_datasheet_km_is_kept():
    m = _fitted("datasheet")
    follow_ke(m, m.value("km"))
    assert m.value("km") == pytest.approx(0.05 * 1.0786) and m.value("J") == pytest.approx(
        TRUE["J"] * 1.0786)
