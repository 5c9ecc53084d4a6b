"""Once diagnose takes the armature's lag, the dead zone is read with it (diagnose/lagdz.py).

Round trip through ``identify`` (with diagnose) on ``bench/lawlag.py``'s rig: a bench motor
with back-EMF and an L/R of 2 ms (one sample at 500 Hz: fit-mechanical's steps leave the lag
unresolved and the joint fit settles dz' on the applied voltage), every parameter moved up to
20 % by the seed, speed noise 0.5 rad/s from ``default_rng``. At main (f14047c) diagnose took
the lag but wrote dz' as the interval the lag-less fit settled: [0, 0.0516] V with the truth
0.0686 V outside on seed 10.
"""

from __future__ import annotations

import math

import pytest

from bench.lawlag import per_volt, scenario
from pmdcid.api import identify
from pmdcid.diagnose import lagdz
from pmdcid.diagnose.lagdz import spread_within, widen
from pmdcid.fit.results import Estimate


def test_the_spread_across_a_masked_dead_zone_widens_the_others():
    pts = [{"J": 1.0, "bc": 0.5, "dz": 0.0}, {"J": 1.0 + math.sqrt(12.0), "bc": 0.5, "dz": 1.0}]
    spread = spread_within(pts, ["J", "bc", "dz"])
    assert spread == pytest.approx({"J": 1.0, "bc": 0.0})
    est = {"J": Estimate("J", 1.0, 1.0, "V s^2/rad"), "bc": Estimate("bc", 0.5, 0.1, "V")}
    widen(est, spread)
    assert est["J"].stderr == pytest.approx(math.sqrt(2.0))
    assert est["bc"].stderr == 0.1  # no spread: unchanged
    assert spread_within(pts[:1], ["J"]) == {}  # one point: no spread to read


def test_the_note_on_the_refitted_profile_says_the_value_written(monkeypatch):
    """The values written stay the fit's (refitted_line's docstring); the note said "dz = 2.0804
    +- 0.058: the middle of its profile-likelihood interval" beside a model file holding 2.6982
    (bench/thinlogs.py b2:viscous_asymmetry seed 39, before session 38's fix of the nudge)."""
    from types import SimpleNamespace

    moved = {"dz": Estimate("dz", 2.0804, 0.058, "V"), "J": Estimate("J", 0.0109, 4e-5, "")}
    monkeypatch.setattr(lagdz, "refit_interval", lambda refit, shim: (moved, "dz = 2.0804 ..."))
    monkeypatch.setattr(lagdz, "refitter", lambda run, free, vals: lambda dz, start: None)
    est = {"dz": Estimate("dz", 2.6982, 0.05, "V"), "J": Estimate("J", 0.0108, 4e-5, "")}
    final = SimpleNamespace(values={"dz": 2.6982, "J": 0.0108}, estimates=dict(est))
    notes: list[str] = []
    lagdz.refitted_line(None, final, ["J", "dz"], None, notes)
    assert final.estimates["dz"].value == 2.6982 and final.estimates["dz"].stderr == 0.058
    assert notes[0].startswith("dz = 2.6982 ± 0.058: the fit's value")
    assert "the interval's middle 2.0804" in notes[0]


@pytest.mark.slow
def test_the_dead_zone_is_read_with_the_lag_diagnose_took():
    fit, _, vals = scenario(10, 2.0, 500.0, "none")
    model = identify(fit, diagnose=True, progress=False).model
    assert model.has("tau_e")  # diagnose took the lag (fit-mechanical had not)
    true = per_volt(vals)["dz"]
    p = model.parameters["dz"]
    if p.interval is not None:
        assert p.interval[0] <= true <= p.interval[1], (p.interval, true)
    else:
        assert abs(p.value - true) <= 2.0 * p.stderr, (p.value, p.stderr, true)
