"""diagnose's parts alone: which logs are held out, the repeatability floor, the one rule set
with its reasons, failed and degenerate refits, and the residual's shape in physical terms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from ident_util import as_log

from pmdcid.diagnose.candidates import Candidate
from pmdcid.diagnose.folds import holdout_plan, protocol_key, repeat_groups, repeatability
from pmdcid.diagnose.loop import accept
from pmdcid.diagnose.rules import Rules, at_bound, failed_refit, judge
from pmdcid.diagnose.shape import _angle_shape, _speed_shape, _time_shape


def _run_log(name, u, w, t0=0.0, dt=1e-3):
    t = t0 + np.arange(len(u)) * dt
    return as_log(name, t, {"v": u, "omega": w})


@pytest.mark.parametrize("path,key", [("a/step_3.csv", "step"), ("step_6V_2.csv", "step_6V"),
                                      ("triangle.csv", "triangle"), ("step_1.0V", "step_1.0V")])
def test_protocol_key(path, key):
    assert protocol_key(path) == key


def test_repeats_are_held_out_whole_and_single_logs_split():
    rng = np.random.default_rng(1)
    u = np.where(np.arange(3000) > 500, 12.0, 0.0)
    logs = [_run_log(f"step_{k}.csv", u, rng.normal(size=3000)) for k in range(1, 4)]
    logs.append(_run_log("step_4.csv", 0.5 * u, rng.normal(size=3000)))  # another amplitude
    logs.append(_run_log("sine.csv", np.sin(np.arange(3000) / 100), rng.normal(size=3000)))
    assert repeat_groups(logs) == [[0, 1, 2]]
    assert holdout_plan(logs) == ["fit", "fit", "held", "split", "split"]


def test_repeats_with_trimmed_starts_align_on_time():
    """A run whose first samples were cut keeps its time stamps: still a repeat."""
    t = np.arange(4000) * 1e-3
    u = np.where(t > 1.0, 12.0, 0.0)
    a = as_log("sine_1.csv", t, {"v": u, "omega": u})
    b = as_log("sine_2.csv", t[150:], {"v": u[150:], "omega": u[150:]})
    assert repeat_groups([a, b]) == [[0, 1]]


def test_repeatability_floor_round_trip():
    """Runs = one response + independent noise sigma: each run against the mean of the other
    (n - 1) differs by sigma sqrt(1 + 1/(n - 1)); the floor is that over the run's std."""
    rng = np.random.default_rng(2)
    n, sigma = 4, 0.5
    t = np.arange(20000) * 1e-3
    u = np.sign(np.sin(2 * np.pi * 0.5 * t))
    w = 10 * np.sin(2 * np.pi * 0.5 * t)
    logs = [as_log(f"sq_{k}.csv", t, {"v": u, "omega": w + rng.normal(0, sigma, len(t))})
            for k in range(n)]
    (fl,) = repeatability(logs)
    expect = sigma * math.sqrt(1 + 1 / (n - 1)) / math.sqrt(np.var(w) + sigma**2)
    assert fl.value == pytest.approx(expect, rel=0.03)


def _cand(name, **kw):
    base = {"delta_bic": -500.0, "heldout": -200.0, "z": 20.0, "gain_fit": 0.2,
            "gain_held": 0.2, "status": "refitted", "chi2_fit": 1000.0}
    base.update(kw)
    c = Candidate(name, 1, 1.0, base.pop("delta_bic"), True)
    for k, v in base.items():
        setattr(c, k, v)
    return c


@pytest.mark.parametrize("kw,words", [
    ({"delta_bic": -5.0}, "ΔBIC -5.0 ≥ -10"),
    ({"heldout": 3.0}, "held-out Δ +3.0 ≥ -10"),
    ({"z": 0.9}, "size 0.9 standard errors < 5"),
    ({"gain_held": 0.003}, "held-out gain 0.3 % < 1.0 %"),
    ({"rise": 0.12, "rise_log": "step_6.csv"}, "step_6.csv rises 12.0 % > 5.0 %"),
])
def test_every_refusal_names_its_rule_and_number(kw, words):
    ok, why = judge(_cand("x", **kw), Rules())
    assert not ok and words in why, why


def test_failed_and_degenerate_refits_are_never_counted():
    good = _cand("good", delta_bic=-50.0, chi2_fit=900.0)
    failed = _cand("failed", delta_bic=-9000.0, status="refit failed", chi2_fit=800.0,
                   reason="refit failed")
    bound = _cand("bound", delta_bic=-8000.0, status="degenerate", chi2_fit=700.0)
    twin_a = _cand("twin_a", delta_bic=-7000.0, chi2_fit=600.0)
    twin_b = _cand("twin_b", delta_bic=-7000.0, chi2_fit=600.0)
    best = accept([good, failed, bound, twin_a, twin_b], Rules())
    assert best is good and good.chosen and good.reason.startswith("chosen")
    assert failed.reason == "refit failed" and not failed.chosen
    assert "identical to twin_a" in twin_b.reason and "identical to twin_b" in twin_a.reason
    assert twin_a.status == twin_b.status == "degenerate"


def test_refit_failure_and_bounds():
    assert failed_refit(101.0, 100.0) and not failed_refit(99.0, 100.0)
    assert at_bound(1000.0, 0.0, 1000.0) == "upper"
    assert at_bound(1e-6, 1e-6, 1e6) == "lower"
    assert at_bound(500.0, 0.0, 1000.0) is None
    assert at_bound(0.0, 0.0, 1.0) is None  # a zero bound is the neutral value, not a wall


def test_shapes_in_physical_terms():
    rng = np.random.default_rng(3)
    dt = 1e-3
    t = np.arange(60000) * dt
    w = 50 * np.sin(2 * np.pi * 0.1 * t)
    noise = rng.normal(0, 0.05, len(t))
    # friction flattening with speed: the error grows with |omega|, signed by the direction
    sp = _speed_shape(0.01 * w * np.abs(w) / 50 + noise, w)
    assert sp and "grows with |ω|" in sp["description"] and "friction" in sp["description"]
    # a 47 Hz line in time
    fr = _time_shape(0.3 * np.sin(2 * np.pi * 47 * t) + noise, dt, t[-1])
    assert fr and fr["frequency_hz"] == pytest.approx(47, rel=0.01)
    # cogging: 6 per revolution of the angle
    theta = np.cumsum(w) * dt
    an = _angle_shape(0.3 * np.sin(6 * theta) + noise, w, dt)
    assert an and an["per_revolution"] == 6 and "cogging" in an["description"]
    # white noise has no shape
    assert _speed_shape(noise, w) is None and _time_shape(noise, dt, t[-1]) is None
    assert _angle_shape(noise, w, dt) is None


class _Fit:
    def __init__(self, values, chi2):
        self.values, self.chi2 = values, {"fit": chi2}


class _FakeRun:
    """Refits whose fit-part chi-square is a known function of the start: the guess's own
    start lands above the model it extends; only a start with the effect 3x larger is good."""

    def __init__(self, good_from):
        self.good_from = good_from
        self.starts = []

    def _fo(self, start):
        self.starts.append(dict(start))
        return _Fit(start, 50.0 if start.get("tau0", 0.0) >= self.good_from else 120.0)

    def robust_fit(self, start, free, part="fit"):
        return self._fo(start)

    def fit(self, start, free, part="fit"):
        return self._fo(start)


def test_failed_refit_is_retried_from_other_starts():
    from pmdcid.diagnose.candidates import refit_starts
    from pmdcid.diagnose.screen import Screen

    cur = _Fit({"J": 1.0, "tau0": 0.0}, 100.0)
    scr = Screen("torque_offset", 1.0, start={"tau0": 1.0})
    run = _FakeRun(good_from=2.0)
    best, n = refit_starts(run, scr, cur, ["tau0"])
    # guess, effect at neutral, then guess x0.3 and x3: the last one is the good refit
    assert [s["tau0"] for s in run.starts] == [1.0, 0.0, 0.3, 3.0] and n == 4
    assert best.chi2["fit"] == 50.0
    # when the first starts already improve on the model, no retry
    run = _FakeRun(good_from=1.0)
    best, n = refit_starts(run, scr, cur, ["tau0"])
    assert n == 2 and best.chi2["fit"] == 50.0
    # all starts worse than the model: the best failed one comes back, for the row to flag
    run = _FakeRun(good_from=100.0)
    best, n = refit_starts(run, scr, cur, ["tau0"])
    assert n == 4 and failed_refit(best.chi2["fit"], cur.chi2["fit"])


def _torque_log(truth, rng, seconds=20.0, name="tau.csv"):
    from pmdcid.io import Log
    from pmdcid.synth import PAPER_NOISE, synth_log, triangle

    t = np.arange(int(seconds * 1000)) / 1000.0
    tau = 0.04 * triangle(t, 1.0, 10.0) + 0.01 * np.sin(2 * np.pi * 0.7 * t)
    cols, _ = synth_log(t, tau, truth, PAPER_NOISE, rng, torque_driven=True)
    return Log(path=name, t=t, data=cols)


def _truth(**extra):
    from pmdcid.simulate import neutral_values
    from pmdcid.synth import PAPER

    return {**neutral_values(), **PAPER, "dz": 0.0, **extra}


@pytest.mark.parametrize("tau0,kept", [(0.0, False), (2e-3, True)])
def test_final_model_keeps_only_what_it_supports(tau0, kept):
    """An effect handed to the final step is kept only when the final fit on all the data puts
    it at least 5 standard errors from neutral; otherwise it is removed with a note giving its
    size, and the rest refitted."""
    from pmdcid.diagnose.final import finalise
    from pmdcid.diagnose.loop import Run, baseline
    from pmdcid.diagnose.settings import Settings
    from pmdcid.fit.problem import Problem
    from pmdcid.model import Model

    truth = _truth(tau0=tau0)
    log = _torque_log(truth, np.random.default_rng(41))
    model = Model()
    for k in ("J", "bv", "bc"):
        model.set(k, truth[k])
    problem = Problem([log], plan=["split"])
    run = Run(problem, model, Settings())
    cur = baseline(run)
    added, notes = ["torque_offset"], []
    final, free = finalise(run, cur, added, notes, [])
    assert (added == ["torque_offset"]) is kept, notes
    if kept:
        assert final.values["tau0"] == pytest.approx(tau0, rel=0.1)
    else:
        assert "tau0" not in free
        assert any(n.startswith("torque_offset removed:") and "< 5" in n for n in notes), notes


def test_drift_is_compared_only_where_it_can_show():
    """A step's plateau is never compared with its transient; a periodic input's two parts
    are; repeats are compared run against run."""
    from pmdcid.diagnose.folds import holdout_plan
    from pmdcid.diagnose.residuals import drift_problem
    from pmdcid.fit.problem import Problem

    rng = np.random.default_rng(5)
    t = np.arange(6000) / 1000.0
    u = np.where(t > 0.5, 2.0, 0.0)
    w = 100 * (1 - np.exp(-np.clip(t - 0.5, 0, None) / 0.3)) + rng.normal(0, 0.1, len(t))
    step = as_log("step.csv", t, {"v": u, "omega": w})
    tri = as_log("tri.csv", t, {"v": np.sin(2 * np.pi * t), "omega": 50 * np.sin(2 * np.pi * t)})
    assert drift_problem(Problem([step], plan=["split"])) is None
    dp = drift_problem(Problem([step, tri], plan=["split", "split"]))
    assert [lg.path for lg in dp.logs] == ["tri.csv"]
    runs = [as_log(f"step_{k}.csv", t, {"v": u, "omega": w}) for k in (1, 2, 3)]
    # a log with no repeat (its own split: a step) stays out
    assert holdout_plan(runs + [step]) == ["fit", "fit", "fit", "held"]  # "step" repeats too
    other = as_log("other.csv", t, {"v": 2 * u, "omega": 2 * w})
    dp = drift_problem(Problem(runs + [other], plan=holdout_plan(runs + [other])))
    assert [lg.path for lg in dp.logs] == ["step_1.csv", "step_2.csv", "step_3.csv"]
    assert dp.plan == ["fit", "fit", "held"]


@pytest.mark.parametrize("lumped", [False, True])
def test_unidentified_dead_zone_is_said_in_the_models_unit(monkeypatch, lumped):
    """A dead zone the logs cannot see is written as an interval; its note and estimate speak the
    model's unit: N m, or V for a per-volt (lumped) model."""
    from types import SimpleNamespace

    from pmdcid.diagnose import final as fin
    from pmdcid.fit.problem import FitOutcome
    from pmdcid.fit.results import FitStats
    from pmdcid.model import Model
    from pmdcid.model.lumped import mark_lumped

    model = Model()
    if lumped:
        mark_lumped(model)
    out = FitOutcome({"dz": 0.1, "bc": 0.2}, {}, FitStats(10, 1, 1.0, 1))
    run = SimpleNamespace(problem=None, model=model, fit=lambda vals, free, part: out)
    monkeypatch.setattr(fin, "dead_zone_range", lambda problem, fo: 0.5)
    notes: list[str] = []
    final, free = fin.settle_dead_zone(run, out, ["dz", "bc"], notes)
    unit = "V" if lumped else "N m"
    assert free == ["bc"]
    assert final.estimates["dz"].unit == unit
    assert final.estimates["dz"].value == pytest.approx(0.25)
    assert f"0 to 0.5 {unit} fits equally" in notes[0]
