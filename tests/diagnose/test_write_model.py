"""diagnose's written model: a km written as ke (no datasheet) follows the refitted ke.

Found by issue 24's new-user checks (a brush drop added, ke refitted 0.0539 -> 0.0500, km left
at 0.0539 and J, bv, bc 8 % high at a thousand standard errors); the rule itself is tested in
tests/identify/test_follow_ke.py.
"""

from __future__ import annotations

import pytest

from pmdcid.diagnose.summary import write_model
from pmdcid.fit.problem import FitOutcome
from pmdcid.fit.results import Estimate, FitStats
from pmdcid.identify.freerun import KM_FROM_KE
from pmdcid.synth import truth_model


def test_refitted_ke_carries_km_and_the_torque_parameters():
    m = truth_model({"R": 2.43, "L": 4e-3, "ke": 0.0539, "J": 1.35e-4, "bv": 2e-6, "bc": 2e-3},
                    ["back_emf"])
    m.set("km", 0.0539, 7.8e-4, "N m/A", stage=KM_FROM_KE)
    est = {"R": Estimate("R", 2.0, 1e-4, "ohm"), "ke": Estimate("ke", 0.05, 1e-6, "V s/rad"),
           "J": Estimate("J", 1.35e-4, 1e-8, "kg m^2"), "vb": Estimate("vb", 0.8, 1e-4, "V")}
    out = FitOutcome(values={"vb": 0.8}, estimates=est, stats=FitStats(ndata=10, nvarys=4,
                                                                       chisqr=10.0))
    write_model(m, out, list(est), ["brush_drop"])
    assert m.value("km") == m.value("ke") == 0.05
    assert m.value("J") == pytest.approx(1.35e-4 * 0.05 / 0.0539, rel=1e-12)
    assert m.value("bc") == pytest.approx(2e-3 * 0.05 / 0.0539, rel=1e-12)
    assert m.value("R") == 2.0 and m.value("vb") == 0.8
