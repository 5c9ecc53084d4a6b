"""diagnose/starts.py: the switching parameters' profile standard error is the profile's own
width, never the scan's step printed as an uncertainty."""

from __future__ import annotations

import math

import pytest

from pmdcid.diagnose.starts import profile_stderr


class Parabola:
    """chi2(x) = ((x - centre) / width)^2: the standard error is ``width``."""

    def __init__(self, centre: float, width: float):
        self.centre, self.width = centre, width

    def chi2(self, vals):
        return {"all": ((vals["bc"] - self.centre) / self.width) ** 2}


@pytest.mark.parametrize("rel", [0.05, 3e-3, 2e-4])
def test_profile_stderr_is_the_profile_width_not_the_scan_step(rel):
    p = Parabola(0.005, rel * 0.005)
    se = profile_stderr(p, {"bc": 0.005}, "bc", redchi=1.0)
    assert se == pytest.approx(rel * 0.005, rel=0.15)


def test_profile_stderr_unresolved_is_nan_not_a_floor():
    p = Parabola(0.005, 1e-12)
    assert math.isnan(profile_stderr(p, {"bc": 0.005}, "bc", redchi=1.0))
