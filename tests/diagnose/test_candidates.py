"""Which parameters can stand in for a candidate on held-out data (candidates.stand_ins)."""

from __future__ import annotations

import pytest

from pmdcid.diagnose.candidates import stand_ins

CURVE = ["fc1", "fc2", "fc3"]


def test_a_friction_law_already_in_the_model_stands_in_for_a_new_one():
    free = ["dbv", "J", "bv", "bc", *CURVE]
    # one log per direction: an asymmetry of bv is the curve's shape at a second speed
    # (and J, the lag: a speed law's change reaches held-out data through the inherited state)
    assert stand_ins("viscous_asymmetry", free) == ["J", "bv", *CURVE]
    assert stand_ins("quadratic_drag", ["bq", "J", "bv", "bc", "dbv"]) == ["J", "bv", "dbv"]
    # the base parameters it interacts with, without another effect: as before
    assert stand_ins("quadratic_drag", ["bq", "J", "bv", "bc", "tau_e"]) == ["J", "bv", "tau_e"]


def test_effects_that_share_nothing_do_not_stand_in():
    assert stand_ins("sensor_delay", ["delay", "J", "bv", "bc", *CURVE]) == []
    assert stand_ins("brush_drop", ["vb", "R", "L", "J", "bv", "bc", *CURVE]) == ["R"]
    # a candidate's own parameters are never among them
    assert "bq" not in stand_ins("quadratic_drag", ["bq", "bv", *CURVE])


def test_an_effect_whose_size_is_not_determined_has_no_size():
    """A refit that leaves the effect's parameter without a standard error (its variance not
    positive: NaN, 'not determined') gives a size of 0 standard errors, not infinitely many
    (which passed the size rule)."""
    import math
    from types import SimpleNamespace

    from pmdcid.diagnose.candidates import effect_z
    from pmdcid.fit.results import fitted
    from pmdcid.model import EFFECTS

    eff = EFFECTS["torque_offset"]
    fo = SimpleNamespace(estimates={"tau0": fitted("tau0", 0.01, math.nan, "N m")})
    assert effect_z(eff, fo) == 0.0
    fo = SimpleNamespace(estimates={"tau0": fitted("tau0", 0.01, 0.002, "N m")})
    assert effect_z(eff, fo) == pytest.approx(5.0)
