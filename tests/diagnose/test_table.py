"""diagnose's printed table: an added effect's parameters with their errors, or words."""

import math
from types import SimpleNamespace

from pmdcid.diagnose.table import _added_lines
from pmdcid.model import Model


def test_an_added_parameter_without_a_standard_error_says_so_in_words():
    m = Model()
    m.set("tau0", 0.012, 0.001)
    m.set("delay", 0.004, math.nan, caveat="not determined by these logs")
    res = SimpleNamespace(summary={"added": ["torque_offset", "sensor_delay"]}, model=m)
    lines = _added_lines(res)
    assert "tau0 = 0.012 ± 0.001" in lines[0]
    assert lines[1].endswith("delay = 0.004 s (not determined by these logs)"), lines[1]
    m.set("delay", 0.004, math.nan)
    assert _added_lines(res)[1].endswith("(no standard error)")
