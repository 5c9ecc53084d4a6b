"""fit-mechanical on real rigs' step logs (../shared/data/real, read in place, never copied).

Checks that do not need the truth: repeats agree with one another, two protocols (single steps and
a pulse staircase whose steps return to 0 V) agree, the steady-speed line matches the rig README's
independent quick check, no dead time is invented, and a one-sample counter glitch is cleaned.
"""


import numpy as np
import pytest
from repo_paths import REAL

from pmdcid.identify.mechanical import fit_mechanical, steady_line
from pmdcid.io import read_log
from pmdcid.model import Model

REAL = REAL
pytestmark = pytest.mark.skipif(not REAL.is_dir(), reason=f"{REAL} is absent (the real rigs' "
                                "logs live outside the repository)")


def _fit(rig, names):
    m = Model()
    m.set("R", 3.4)  # Kmot, tau_mot and the line do not depend on R, L, km
    m.set("L", 2.85e-3)
    return fit_mechanical([read_log(REAL / rig / n) for n in names], m, km=1.0)


def _by_level(res):
    out = {}
    for s in res.steps:
        if s.moved:
            out.setdefault(round(s.level, 2), []).append(s)
    return out


@pytest.mark.parametrize("rig,names", [
    ("fra233-g04", [f"step_{k}.csv" for k in range(1, 7)]),
    ("guanlunlu-l298n", [f"step_{v}V_{k}.csv" for v in (6, 12, 24) for k in (1, 2, 3)]),
])
def test_repeats_agree_and_no_dead_time_is_invented(rig, names):
    res = _fit(rig, names)
    assert all(s.moved and s.from_rest for s in res.steps)
    for level, steps in _by_level(res).items():
        k = np.array([s.kmot for s in steps])
        tau = np.array([s.tau_mot for s in steps])
        assert np.std(k, ddof=1) < 0.01 * k.mean(), level
        assert np.std(tau, ddof=1) < 0.15 * tau.mean(), level
        assert max(s.dead_time for s in steps) < 0.01, level  # the rigs' latency: a few ms


def test_line_matches_the_readme_quick_check():
    """guanlunlu-l298n README: steady speeds linear in voltage, slope about 1.43 rad/s per V,
    intercept about 2.4 V (the L298N's drop plus friction)."""
    res = _fit("guanlunlu-l298n", [f"step_{v}V_{k}.csv" for v in (6, 12, 24) for k in (1, 2, 3)])
    mv = [s for s in res.steps if s.moved]
    a, c, _ = steady_line(np.array([s.level for s in mv]), np.array([s.omega_ss for s in mv]),
                          np.array([s.omega_ss_se for s in mv]))
    assert a == pytest.approx(1.43, rel=0.03)
    assert -c / a == pytest.approx(2.4, abs=0.3)


def test_staircase_steps_agree_with_single_steps():
    """fra233-g04: the pulse staircase (3, 0, 6, 0, 9, 0, 12, 0 V: steps up from rest, the first
    at the log's first sample, each followed by a step down to 0 V) gives the single-step logs'
    12 V Kmot within 1 %, tau within 15 %; the steps down to 0 V are reported, not fitted."""
    steps = _by_level(_fit("fra233-g04", ["step_1.csv", "step_2.csv"]))[12.0]
    res = _fit("fra233-g04", ["stair_1.csv", "stair_2.csv"])
    stair = _by_level(res)[12.0]
    assert np.mean([s.kmot for s in stair]) == pytest.approx(
        np.mean([s.kmot for s in steps]), rel=0.01)
    assert np.mean([s.tau_mot for s in stair]) == pytest.approx(
        np.mean([s.tau_mot for s in steps]), rel=0.15)
    assert sum(s.note == "coasts to rest" for s in res.steps) == 8
    # 3 V is applied at the first sample with the rotor at rest (omega 0 for 50 ms): a step from
    # rest like lego-ev3's, used since loop-timed logs were read (identify/steps.py, at_start)
    assert sorted(_by_level(res)) == [3.0, 6.0, 9.0, 12.0]


def test_a_counter_glitch_is_cleaned():
    res = _fit("guanlunlu-l298n", ["step_duty100_12.24V.csv"])
    assert any("spike" in w for w in res.warnings)
    assert res.steps[0].kmot == pytest.approx(1.12, rel=0.03)
