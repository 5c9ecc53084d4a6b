"""Real rigs (../shared/data, never copied here): fit on some logs, predict the others.

The same rules as ``make realbench`` (bench/realdata.py): held-out speed NRMSE of ``identify``
(no diagnose, to keep the suite fast) and of the paper's stage sequence, against a linear
first-order model fitted on the same logs and the rig's repeatability floor. Skipped only when
../shared/data is absent (CI has it).
"""

from __future__ import annotations

import pytest

from bench import realdata

RIGS = {r.name: r for r in realdata.rigs()}
pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not RIGS, reason=f"no real data under {realdata.SHARED}")]


def _check(name: str, *, target: bool, paper: bool = True, paper_target: bool | None = None):
    rig = RIGS.get(name)
    if rig is None:
        pytest.skip(f"{name} not under {realdata.SHARED}")
    models = {"identify": realdata.identify_rig(rig, diagnose=False)}
    if paper:
        models["paper"] = realdata.paper_sequence(rig)
    res = realdata.evaluate(rig, models)
    mean = realdata.summarise(res, list(models))
    for label in models:
        # never above the linear baseline, on the mean and on 80 % of the runs
        assert mean[label] < mean["linear"], (label, mean)
        worse = [r["log"] for r in res["rows"] if r[label] > r["linear"]]
        assert len(worse) <= 0.2 * len(res["rows"]), (label, worse)
        if target and (label != "paper" or paper_target in (None, True)):
            assert mean[label] <= mean["target"], (label, mean)
    return mean


def test_l298n_steps_predict_their_repeats():
    """100 Hz output-shaft speed, a 2.4 V apparent dead zone (driver drop + friction): the
    repeats of each step are predicted within max(linear/2, 1.2 x floor)."""
    _check("guanlunlu-l298n", target=True)


def test_course_lab_steps_and_ramps_predict_sines_chirps_stairs():
    """The course-lab kit: steps and ramps to fit (as the paper and the students do), the other
    protocols held out; the paper's sequence no longer ends worse than linear (the ramps no
    longer move J away from what the steps determined). Both meet the target (0.043): identify
    0.033, the paper's sequence 0.035 now that fit-mechanical keeps the steps' 3.9 ms USB latency
    as sensor_delay (0.044 without it; docs/real-data.md)."""
    _check("fra233-g04", target=True)


def test_emps_estimation_predicts_validation():
    _check("EMPS", target=True, paper=False)


def test_lego_ev3_steps_predict_sines():
    """Loop-timed samples (4-18 ms, put on a uniform grid on reading, docs/io.md) and the duty
    applied from the first sample: fitted on the 20 steps, the paper's sequence predicts the
    three sines below half the linear baseline (issue 24's target: 0.050 against linear 0.131);
    identify without diagnose (this suite's) is asked only to beat linear: 0.064 against the
    target's 0.065 on 2026-11-25, too close to hold it to the target (0.109 before; with
    diagnose 0.059, docs/real-data.md)."""
    mean = _check("lego-ev3", target=False)
    assert mean["paper"] <= mean["target"], mean
