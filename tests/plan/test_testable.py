"""``plan --check`` says which effects diagnose screens these logs could test, and what to
record for the others (issue #24: one log at one operating point adds nothing it cannot test)."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from pmdcid.cli import main
from pmdcid.io.logs import write_log
from pmdcid.model import EFFECTS, save_model
from pmdcid.plan.check import EFFECTS_HEAD
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, truth_model

#: the speed laws and asymmetries a single step cannot test, and a staircase with reversals can
LAWS = ("quadratic_drag", "friction_curve", "viscous_asymmetry", "torque_offset")


def _log(tmp_path, name: str, levels, hold: float, seed: int) -> str:
    """Voltage ``levels`` [V] each held ``hold`` seconds at 1 kHz on the paper motor, speed and
    current logged with the paper's noise."""
    t = np.arange(int(len(levels) * hold * 1000)) / 1000.0
    u = np.asarray(levels, float)[np.minimum((t / hold).astype(int), len(levels) - 1)]
    cols, _ = synth_log(t, u, {**neutral_values(), **PAPER}, PAPER_NOISE,
                        np.random.default_rng(seed))
    path = tmp_path / name
    write_log(path, t, {c: cols[c] for c in ("v", "i", "omega")})
    return str(path)


def _check(tmp_path, log: str) -> tuple[dict, str]:
    model = tmp_path / "m.json"
    save_model(truth_model(PAPER), model)
    res = CliRunner().invoke(main, ["plan", "--check", log, "-m", str(model), "-o",
                                    str(tmp_path / "c")], catch_exceptions=False)
    assert res.exit_code == 0, res.stderr
    rep = json.loads((tmp_path / "c" / "check.json").read_text())
    assert "parameters" in rep and "threshold" in rep  # the keys it had are kept
    return {r["effect"]: r for r in rep["effects"]}, res.stdout


def test_one_step_at_one_operating_point_tests_no_speed_law(tmp_path):
    """0 -> 1.5 V held 3 s: diagnose holds out the steady tail, where a drag law, a friction
    curve and the asymmetries change nothing bv or bc could not."""
    rows, out = _check(tmp_path, _log(tmp_path, "step.csv", [0.0, 1.5, 1.5, 1.5], 1.0, 3))
    for e in LAWS + ("sensor_delay",):
        assert not rows[e]["testable"], rows[e]
        assert rows[e]["record"] == EFFECTS[e].record
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(e + " "))
        assert f"possible, not testable with these logs: record {EFFECTS[e].record}" in line
    assert rows["back_emf"]["testable"]  # the current logged at the tail's speed shows it


def test_a_staircase_with_reversals_tests_them(tmp_path):
    levels = [0.5, 1.0, 2.0, -1.0, 1.5, -2.0, 2.5, 0.8, -1.5, 2.2]
    rows, out = _check(tmp_path, _log(tmp_path, "stairs.csv", levels, 1.0, 4))
    for e in LAWS + ("sensor_delay",):
        assert rows[e]["testable"], rows[e]
        assert rows[e]["record"] is None
        assert any(ln.split() == [e, "testable"] for ln in out.splitlines()), out


def test_a_staircase_turning_one_way_tests_no_direction_effect(tmp_path):
    """The reversing staircase's levels, all positive: its operating points test the speed
    laws, but logs that never reverse cannot tell a direction asymmetry from bc and bv (at main
    viscous_asymmetry was called testable here, by the two columns' curvature: 1684 chi-square
    against a floor of 81)."""
    from pmdcid.diagnose.testable import ONE_WAY

    levels = [0.5, 1.0, 2.0, 0.3, 1.5, 0.6, 2.5, 0.8, 1.2, 2.2]
    rows, out = _check(tmp_path, _log(tmp_path, "oneway.csv", levels, 1.0, 4))
    for e in ("viscous_asymmetry", "torque_offset"):
        assert not rows[e]["testable"], rows[e]
        assert ONE_WAY in rows[e]["why"]
        assert "both directions" in rows[e]["record"]
        line = next(ln for ln in out.splitlines() if ln.strip().startswith(e + " "))
        assert f"possible, not testable with these logs: record {EFFECTS[e].record}" in line
    for e in ("quadratic_drag", "friction_curve"):  # several speeds: the laws are testable
        assert rows[e]["testable"], rows[e]


def test_only_effects_diagnose_screens_are_judged(tmp_path):
    """lugre is searched only when asked (--effect), and an effect the model has is not a
    candidate: neither is listed."""
    log = _log(tmp_path, "step.csv", [0.0, 1.5, 1.5], 1.0, 5)
    model = truth_model(PAPER)
    model.add_effect("stribeck")
    model.set("fs", 0.002)
    model.set("ws", 5.0)
    save_model(model, tmp_path / "m.json")
    res = CliRunner().invoke(main, ["plan", "--check", log, "-m", str(tmp_path / "m.json")],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.stderr
    listed = {ln.split()[0] for ln in res.stdout.split(EFFECTS_HEAD)[1].splitlines()
              if ln.strip()}
    assert "lugre" not in listed and "stribeck" not in listed and "quadratic_drag" in listed
