"""A bounded parameter whose standard error spans its whole declared range (issue 24, Build 3:
"a bound is never printed as a standard error"): the model file writes no standard error and
says why, for every parameter with a range closed on both sides, base or effect."""

from __future__ import annotations

import json
import math

import pytest

from pmdcid.model import Model, save_model
from pmdcid.model.effects import bounds_of, range_only
from pmdcid.model.spec import spans_range


def test_spans_range_only_for_a_closed_range_covered_by_two_errors():
    assert spans_range(1e-4, 0.58, 0.0, 1.0)  # 1e-4 - 1.16 <= 0, 1e-4 + 1.16 >= 1
    assert spans_range(0.5, 0.25, 0.0, 1.0)  # exactly the range: nothing from the logs
    assert not spans_range(0.9, 0.2, 0.0, 1.0)  # [0.5, 1.3]: share below 0.5 ruled out
    assert not spans_range(0.5, 1e9, 0.0, math.inf)  # open above: no range to span
    assert not spans_range(0.5, math.nan, 0.0, 1.0)  # no error: nothing to judge


def test_model_writes_a_share_spanning_its_range_without_a_standard_error(tmp_path):
    """identify's ke_share 9.7e-05 ± 0.58 (bench/lawlag.py --family share03, 500 Hz, L/R
    2 ms, seed 2): null in the file, the words in its caveat; a share whose error says
    something keeps it."""
    m = Model()
    m.set("ke_share", 9.7e-5, 0.58, stage="diagnose")
    m.set("J", 0.011, 0.0057, stage="diagnose")
    save_model(m, tmp_path / "m.json")
    d = json.loads((tmp_path / "m.json").read_text())["parameters"]
    assert d["ke_share"]["stderr"] is None
    assert "bounded only by its range [0, 1]" in d["ke_share"]["caveat"]
    assert d["ke_share"]["value"] == 9.7e-5  # the value the simulations use is kept
    assert d["J"]["stderr"] == 0.0057 and "caveat" not in d["J"]
    m.set("ke_share", 0.9, 0.2, stage="diagnose", caveat="why")
    assert m.parameters["ke_share"].stderr == 0.2 and m.parameters["ke_share"].caveat == "why"


@pytest.mark.parametrize("name", ["tau_e", "ke_share", "dz_slope", "cphi", "cn"])
def test_every_closed_range_follows_the_one_rule(name):
    lo, hi = bounds_of(name)
    mid, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
    assert range_only(name, mid, 0.5 * half)  # +-2 se: exactly the range
    assert not range_only(name, mid, 0.4 * half)
    m = Model()
    m.set(name, mid, half, caveat="kept")
    p = m.parameters[name]
    assert math.isnan(p.stderr) and p.caveat.endswith("; kept")


def test_open_or_wide_ranges_keep_their_standard_errors():
    """Open above (vmax), or the wide safety range of a scale parameter (J, R: up to 1e6):
    only an error as wide as that range itself is none."""
    assert not range_only("vmax", 12.0, 1e12)
    for name in ("J", "bv", "R", "tau0", "omega0"):
        assert not range_only(name, 1.0, 1e3)
    assert range_only("J", 1.0, 1e6)


def test_a_value_at_its_bound_is_written_as_the_interval_it_leaves():
    """A fit that stops at a bound (bc at 0, the share at 1) reads a one-sided curvature: its
    ``4e-14 +- 0.0098`` would put half of the 95 % interval where the parameter cannot go. It
    is written and shown as the interval from the bound two standard errors into the range,
    with the words; a value a hundredth of a standard error or more inside is an estimate."""
    from pmdcid.fit.results import Estimate, shown
    from pmdcid.model.spec import AT_BOUND_SE, bound_reach

    assert bound_reach(4e-14, 0.0098, 0.0, 1e6) == (0.0, pytest.approx(0.0196))
    assert bound_reach(1.0, 0.1, 0.0, 1.0) == (pytest.approx(0.8), 1.0)
    assert bound_reach(2 * AT_BOUND_SE * 0.0098, 0.0098, 0.0, 1e6) is None
    assert bound_reach(0.0, math.nan, 0.0, 1e6) is None  # no error: nothing to replace
    m = Model()
    m.set("bc", 3e-20, 4.9e-15, caveat="kept")
    p = m.parameters["bc"]
    assert math.isnan(p.stderr) and p.interval == (0.0, pytest.approx(9.8e-15))
    assert p.caveat.startswith("at its bound 0") and p.caveat.endswith("; kept")
    s = str(shown(Estimate("ke_share", 1.0, 0.1, "1")))
    assert s.startswith("ke_share: between 0.8 and 1 (at its bound 1")
    assert shown(Estimate("ke_share", 0.5, 0.1, "1")).interval is None
    assert shown(Estimate("ke_share", 1e-4, 0.58, "1")).interval is None  # spans [0, 1]: none
