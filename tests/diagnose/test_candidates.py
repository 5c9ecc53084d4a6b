"""Which parameters can stand in for a candidate on held-out data (candidates.stand_ins)."""

from __future__ import annotations

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
