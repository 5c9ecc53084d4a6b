"""An inductance the logs do not determine, carried into the speed steps' errors
(:mod:`pmdcid.identify.inductance`)."""

from __future__ import annotations

import math
from types import SimpleNamespace

from pmdcid.fit.results import Estimate
from pmdcid.identify.inductance import carry_inductance_error
from pmdcid.model import Model


def test_an_unknown_error_stays_unknown():
    """L = 1 +- 0.5 mH moves J by +-2e-6 and bv by nothing: J's error gets that part, while
    bv's error, which the fit did not give (one step, no scatter), stays unknown instead of
    being printed as +- 0 (before: the L part alone, 0)."""
    m = Model()
    m.set("L", 1e-3, 5e-4, "H", stage="fit-electrical")
    res = SimpleNamespace(warnings=[], estimates={
        "J": Estimate("J", 1e-4, 1e-6, "kg m^2"), "bv": Estimate("bv", 2e-6, math.nan,
                                                                  "N m s/rad")})

    def refit(model):
        dL = model.value("L") - 1e-3
        return {"J": Estimate("J", 1e-4 + 4e-3 * dL, 1e-6, "kg m^2"),
                "bv": Estimate("bv", 2e-6, math.nan, "N m s/rad")}

    carry_inductance_error(res, m, refit)
    assert math.isclose(res.estimates["J"].stderr, math.hypot(1e-6, 2e-6), rel_tol=1e-9)
    assert math.isnan(res.estimates["bv"].stderr)
    assert res.warnings
