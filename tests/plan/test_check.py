"""plan -> record -> identify closes: a plan's profiles, recorded on a known synthetic rig (the
kernel with sensor noise from ``default_rng(seed)``, through ``pmdcid simulate``), identified by
``pmdcid identify``, give J, bv, bc, dz within 3 standard errors of the truth: the plan's
predicted ones (``plan -m``), identify's own (``plan --guess``, which predicts nothing)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from pmdcid.cli import main
from pmdcid.model import load_model, save_model
from pmdcid.synth import PAPER, truth_model

MECH = ("J", "bv", "bc", "dz")


def _run(*args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    assert res.exit_code == 0, (args[0], res.output, res.stderr)
    return res


def _record(plan_dir: Path, truth: Path, noise: dict, seed: int) -> list[str]:
    """Each profile simulated on the truth with noise (the rig's recording)."""
    rec = plan_dir / "rec"
    rec.mkdir()
    out = []
    for k, prof in enumerate(json.loads((plan_dir / "plan.json").read_text())["profiles"]):
        dst = rec / prof["file"]
        _run("simulate", plan_dir / prof["file"], "-m", truth, "-o", dst, "--noise-i",
             noise["i"], "--noise-omega", noise["omega"], "--seed", seed + k)
        out.append(str(dst))
    return out


@pytest.fixture(scope="module")
def truth(tmp_path_factory):
    path = tmp_path_factory.mktemp("truth") / "truth.json"
    save_model(truth_model(PAPER), path)
    return path


@pytest.mark.slow  # a round trip of seconds: make test, not test-fast
def test_plan_for_a_model_recorded_and_identified_within_its_predicted_stderr(tmp_path, truth):
    _run("plan", "-m", truth, "--vmax", 12, "--budget", 60, "-o", tmp_path / "plan")
    plan = json.loads((tmp_path / "plan" / "plan.json").read_text())
    # the blocked-rotor step says what it draws: V/R = 12 V / 2.37 ohm
    assert any(f"draws {12 / PAPER['R']:.3g} A" in n for n in plan["notes"]), plan["notes"]
    logs = _record(tmp_path / "plan", truth, plan["noise"], seed=7)
    _run("identify", *logs, "-m", tmp_path / "new.json", "--km", PAPER["km"])
    model = load_model(tmp_path / "new.json")
    se = plan["predicted_stderr"]
    z = {n: (model.value(n) - PAPER[n]) / se[n] for n in MECH}
    assert all(abs(v) <= 3 for v in z.values()), z
    used = model.extra["fits"]["identify"]["logs"]
    assert all(v["kind"] != "unused" for v in used.values())


def test_guess_plan_recorded_and_identified_to_a_full_model(tmp_path, truth):
    _run("plan", "--guess", "--vmax", 12, "-o", tmp_path / "plan")
    logs = _record(tmp_path / "plan", truth, {"i": 0.01, "omega": 0.05}, seed=11)
    first = next(p for p in logs if "small_steps" in p)
    rows = [ln for ln in Path(first).read_text().splitlines() if not ln.startswith("#")]
    assert float(rows[1].split(",")[1]) == 0.0  # rest recorded before the first step
    res = _run("identify", *logs, "-m", tmp_path / "new.json", "--km", PAPER["km"])
    assert "small-steps" in res.output
    model = load_model(tmp_path / "new.json")
    z = {n: (model.value(n) - PAPER[n]) / model.parameters[n].stderr for n in MECH}
    assert all(abs(v) <= 3 for v in z.values()), z
    assert "fit-mechanical" in model.extra["fits"]["identify"]["stages"]


def test_simulate_holds_a_blocked_rotor_profile_and_keeps_its_kind(tmp_path, truth):
    _run("plan", "--guess", "--vmax", 12, "-o", tmp_path / "plan")
    src = tmp_path / "plan" / "01_blocked.csv"
    _run("simulate", src, "-m", truth, "-o", tmp_path / "out.csv")
    text = (tmp_path / "out.csv").read_text()
    assert "# kind: blocked-rotor" in text
    header = next(ln for ln in text.splitlines() if not ln.startswith("#"))
    assert header == "t,v,i"  # the rotor held: no speed to spin up


def test_check_sizes_its_fixes_from_the_model_when_the_logs_apply_no_input():
    """plan --check on a log whose input is zeros (the rotor never driven): before, the fixes
    were profiles "up to 0" V, an experiment that excites nothing; now plan's own default input,
    3 x the model's breakaway input, sizes them."""
    import numpy as np

    from pmdcid.io import Log
    from pmdcid.plan import fisher as fi
    from pmdcid.plan.check import check_logs
    from pmdcid.plan.design import DEFAULT_UMAX_BREAKAWAY, Settings, breakaway_input

    rng = np.random.default_rng(7)
    t = np.arange(1000) * 1e-3
    log = Log("idle.csv", t, {"v": np.zeros(t.size), "i": 4e-3 * rng.standard_normal(t.size),
                              "omega": 4e-3 * rng.standard_normal(t.size)})
    model = truth_model(PAPER)
    res = check_logs([log], model, Settings(budget=60))
    drive = fi.drive_of(model)
    top = DEFAULT_UMAX_BREAKAWAY * breakaway_input(fi.model_values(model, drive), drive)
    amps = [fx["amplitude"] for fx in res.fixes.values() if fx.get("kind")]
    assert amps and top > 0
    assert max(amps) == pytest.approx(top, rel=1e-6)


def test_check_of_logs_without_current_still_scores_a_blocked_rotor_fix():
    """Voltage and speed logged, no current: R and L are poorly determined, and the blocked-rotor
    profile that fixes them records the current, whose noise the logs cannot give. Before: an
    internal error (a 0 x 0 information added to the 6 x 6); now plan's default current noise
    (1 % of the stall current at the input limit, or --noise-i) scores it."""
    import numpy as np

    from pmdcid.io import Log
    from pmdcid.plan.check import check_logs
    from pmdcid.plan.design import Settings

    rng = np.random.default_rng(8)
    t = np.arange(1500) * 1e-3
    v = np.where(t > 0.5, 1.5, 0.0)
    log = Log("speed_only.csv", t, {"v": v, "omega": 4e-3 * rng.standard_normal(t.size)})
    res = check_logs([log], truth_model(PAPER), Settings(budget=60))
    assert {"R", "L"} <= set(res.poor())
    assert res.fixes["R"]["kind"] == "blocked"


def test_check_says_a_reversed_speed_as_diagnose_and_report_do(tmp_path):
    """A log of the paper motor (fixtures/paper/truth.json as the model) whose speed sensor
    counts the other way: plan --check says so in speed_against's line, with its fix, and
    check.json keeps it; the same log the right way round says nothing of it."""
    import numpy as np

    from pmdcid.fit.results import speed_against

    truth = Path(__file__).resolve().parents[2] / "fixtures" / "paper" / "truth.json"
    t = np.arange(1500) * 1e-3
    inp = tmp_path / "in.csv"
    inp.write_text("t,v\n" + "".join(f"{a:.3f},{1.5 if a >= 0.1 else 0.0}\n" for a in t))
    _run("simulate", inp, "-m", truth, "-o", tmp_path / "rec.csv", "--noise-i", 0.002,
         "--noise-omega", 0.05, "--seed", int(np.random.default_rng(5).integers(1000)))
    rows = (tmp_path / "rec.csv").read_text().splitlines()
    head = next(k for k, r in enumerate(rows) if not r.startswith("#"))
    cols = rows[head].split(",")
    w, th = cols.index("omega"), cols.index("theta")
    flipped = rows[:head + 1]
    for r in rows[head + 1:]:
        cells = r.split(",")
        cells[w], cells[th] = f"{-float(cells[w])!r}", f"{-float(cells[th])!r}"
        flipped.append(",".join(cells))
    (tmp_path / "flip.csv").write_text("\n".join(flipped) + "\n")

    line = speed_against([(np.ones(3) * [1, 2, 3], -np.ones(3) * [1, 2, 3])]).split(" (")[0]
    res = _run("plan", "--check", tmp_path / "flip.csv", "-m", truth, "-o", tmp_path / "c")
    said = [x for x in res.stderr.splitlines() if line in x]
    assert len(said) == 1 and said[0].startswith(f"warning: {tmp_path / 'flip.csv'}: "), \
        res.stderr
    assert "-c omega=COLUMN*-1" in said[0]
    assert json.loads((tmp_path / "c" / "check.json").read_text())["findings"] == \
        [said[0].split(": ", 2)[2]]
    res = _run("plan", "--check", tmp_path / "rec.csv", "-m", truth)
    assert line not in res.stderr
