"""Nothing is lost: atomic model writes, failed stages leave the model as it was, inputs untouched,
outputs not silently overwritten (policy in docs/data-safety.md).
"""

from __future__ import annotations

import io
import json
import math
import os
import stat
from pathlib import Path

import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.errors import LogError, ModelError
from pmdcid.io import logs as logs_mod
from pmdcid.io.logs import write_log
from pmdcid.model import load_model, save_model
from pmdcid.runtime.outputs import atomic_write, atomic_write_text
from pmdcid.synth import PAPER, truth_model

FIX = FIXTURES


def _model_file(path: Path, values=None) -> bytes:
    save_model(truth_model(values or PAPER), path)
    return path.read_bytes()


def _no_temp_files(folder: Path) -> bool:
    return not [p for p in folder.iterdir() if p.name.endswith(".tmp")]


# ---- atomic replace --------------------------------------------------------------------------

def test_failed_write_leaves_previous_file_and_no_temp(tmp_path):
    target = tmp_path / "model.json"
    old = _model_file(target)

    def half_then_disk_full(fh):
        fh.write('{"parameters": {"R": ')
        raise OSError(28, "No space left on device")

    with pytest.raises(LogError, match="No space left on device"):
        atomic_write(target, half_then_disk_full)
    assert target.read_bytes() == old
    assert _no_temp_files(tmp_path)


def test_interrupted_write_leaves_previous_file_and_no_temp(tmp_path, monkeypatch):
    """Ctrl-C (or any crash) between writing the temporary file and the rename."""
    target = tmp_path / "model.json"
    old = _model_file(target)

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(logs_mod.os, "replace", interrupted)
    m = truth_model({**PAPER, "R": 9.99})
    with pytest.raises(KeyboardInterrupt):
        save_model(m, target)
    assert target.read_bytes() == old
    assert _no_temp_files(tmp_path)


def test_failed_save_model_is_a_model_error_and_keeps_file(tmp_path, monkeypatch):
    target = tmp_path / "model.json"
    old = _model_file(target)

    def full(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(logs_mod.os, "fsync", full)
    with pytest.raises(ModelError):
        save_model(truth_model({**PAPER, "R": 1.0}), target)
    assert target.read_bytes() == old
    assert _no_temp_files(tmp_path)


def test_model_update_keeps_permissions_and_others_parameters(tmp_path):
    target = tmp_path / "model.json"
    _model_file(target)
    os.chmod(target, 0o640)
    m = load_model(target)
    m.set("R", 2.5, 0.01, stage="fit-electrical")
    save_model(m, target)
    assert stat.S_IMODE(target.stat().st_mode) == 0o640
    back = load_model(target)
    assert back.value("R") == 2.5
    assert {k: back.value(k) for k in PAPER if k != "R"} == {k: v for k, v in PAPER.items()
                                                             if k != "R"}


def test_write_log_is_atomic_too(tmp_path, monkeypatch):
    out = tmp_path / "out.csv"
    out.write_text("# generator: pmdcid\nt,v\n0,1\n1,1\n2,1\n")
    old = out.read_bytes()
    monkeypatch.setattr(logs_mod, "WRITE_CHUNK", 10)
    calls = {"n": 0}
    real = logs_mod.np.column_stack

    def failing_chunk(*a, **k):  # the third chunk fails, after two were written
        calls["n"] += 1
        if calls["n"] == 3:
            raise OSError(5, "Input/output error")
        return real(*a, **k)

    monkeypatch.setattr(logs_mod.np, "column_stack", failing_chunk)
    t = logs_mod.np.arange(100) * 1e-3
    with pytest.raises(LogError, match="Input/output error"):
        write_log(out, t, {"v": t * 0 + 1.0})
    assert out.read_bytes() == old
    assert _no_temp_files(tmp_path)


def test_chunked_log_writing_is_identical_to_one_piece(tmp_path, monkeypatch):
    t = logs_mod.np.arange(1001) * 1e-3
    cols = {"v": logs_mod.np.sin(t * 7.0), "i": logs_mod.np.cos(t) / 3.0}
    one = logs_mod.format_csv(t, cols, {"kind": "x"})
    monkeypatch.setattr(logs_mod, "WRITE_CHUNK", 7)
    write_log(tmp_path / "a.csv", t, cols, {"kind": "x"})
    assert (tmp_path / "a.csv").read_text() == one


def test_log_text_is_what_savetxt_writes():
    np = logs_mod.np
    rng = np.random.default_rng(16)
    n = 2000
    t = np.cumsum(rng.uniform(1e-4, 2e-3, n)) + 1.7e9  # epoch seconds: every digit kept
    t[:2] = [0.0, 12.0]  # integral stamps as integers
    v = rng.standard_normal(n) * 10.0 ** rng.integers(-12, 12, n)
    v[:6] = [0.0, -0.0, np.nan, np.inf, -np.inf, 1e300]
    cols = {"v": v, "i": -v / 3.0}
    got = logs_mod.format_csv(t, cols, precision=9)
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([v, -v / 3.0]), delimiter=",", fmt=["%.9g", "%.9g"])
    stamps = ["0", "12", *(repr(x) for x in t[2:].tolist())]  # round-trip: repr
    want = "".join(f"{s},{row}\n" for s, row in zip(stamps, buf.getvalue().splitlines(),
                                                      strict=True))
    assert got == "t,v,i\n" + want
    assert np.array_equal(np.array(stamps, dtype=float), t)


def test_atomic_write_text_round_trip(tmp_path):
    atomic_write_text(tmp_path / "x.txt", "hello\n")
    assert (tmp_path / "x.txt").read_text() == "hello\n"
    assert _no_temp_files(tmp_path)


# ---- simulate's overwrite policy -------------------------------------------------------------

@pytest.fixture
def sim_setup(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "step.csv").write_bytes((FIX / "paper" / "step_1.0V.csv").read_bytes())
    _model_file(tmp_path / "model.json")
    return tmp_path


def _sim(*extra):
    return CliRunner().invoke(main, ["simulate", "step.csv", "-m", "model.json", *extra],
                              catch_exceptions=False)


def test_simulate_refuses_foreign_output_without_force(sim_setup):
    user = b"t,omega\n0,1\n0.001,2\n0.002,3\n"  # a user's own file, not written by pmdcid
    (sim_setup / "out.csv").write_bytes(user)
    res = _sim("-o", "out.csv")
    assert res.exit_code == 1 and "--force" in res.stderr
    assert (sim_setup / "out.csv").read_bytes() == user
    res = _sim("-o", "out.csv", "--force")
    assert res.exit_code == 0, res.stderr
    assert (sim_setup / "out.csv").read_bytes() != user


def test_simulate_replaces_its_own_earlier_output(sim_setup):
    assert _sim("-o", "out.csv").exit_code == 0
    first = (sim_setup / "out.csv").read_bytes()
    assert b"# generator: pmdcid" in first
    save_model(truth_model({**PAPER, "J": 2 * PAPER["J"]}), sim_setup / "model.json")
    res = _sim("-o", "out.csv")
    assert res.exit_code == 0, res.stderr
    assert (sim_setup / "out.csv").read_bytes() != first


@pytest.mark.parametrize("target", ["step.csv", "model.json", "link.csv"])
def test_simulate_never_overwrites_its_inputs_even_forced(sim_setup, target):
    (sim_setup / "link.csv").symlink_to(sim_setup / "step.csv")
    before = {p: (sim_setup / p).read_bytes() for p in ("step.csv", "model.json")}
    res = _sim("-o", target, "--force")
    assert res.exit_code == 1
    assert "would overwrite the" in res.stderr
    assert {p: (sim_setup / p).read_bytes() for p in before} == before


# ---- stages: a failed stage leaves the model byte-for-byte -----------------------------------

STAGES = {
    "fit-electrical": (["paper/blocked_1.0V.csv", "paper/blocked_2.0V.csv"], []),
    "fit-mechanical": (["paper/step_1.0V.csv", "paper/step_2.0V.csv"], ["--km", "0.0502"]),
    "fit-nonlinear": (["paper/triangle.csv"], []),
}


def _stage_available(name):
    if name not in main.commands:
        pytest.skip(f"{name} not available yet")


@pytest.mark.parametrize("stage", STAGES)
def test_failed_stage_leaves_model_byte_for_byte(tmp_path, monkeypatch, stage):
    """The stage reads a good model, then meets a log that cannot be fitted (no excitation)."""
    _stage_available(stage)
    monkeypatch.chdir(tmp_path)
    old = _model_file(tmp_path / "model.json")
    # a flat log: the input never changes and nothing moves
    n = 3000
    (tmp_path / "flat.csv").write_text(
        "t,v,i,omega,theta\n" + "".join(f"{k * 1e-3:.3f},0,0,0,0\n" for k in range(n)))
    res = CliRunner().invoke(main, [stage, "flat.csv", "-m", "model.json", *STAGES[stage][1]],
                             catch_exceptions=False)
    assert res.exit_code == 1, res.stderr
    assert res.stderr.startswith("error: ") and len(res.stderr.strip().splitlines()) == 1
    assert (tmp_path / "model.json").read_bytes() == old
    assert _no_temp_files(tmp_path)


@pytest.mark.parametrize("stage", list(STAGES))
def test_stage_keeps_other_parameters_and_inputs(tmp_path, monkeypatch, stage):
    """A successful stage updates its own parameters, keeps the others, never touches logs."""
    _stage_available(stage)
    monkeypatch.chdir(tmp_path)
    logs, extra = STAGES[stage]
    names = []
    for k, src in enumerate(logs):
        name = f"log{k}.csv"
        (tmp_path / name).write_bytes((FIX / src).read_bytes())
        names.append(name)
    foreign = {"note": "kept", "custom_param": 1.25}
    m = truth_model(PAPER)
    m.set("custom_param", 1.25, stage="user")
    m.extra["note"] = "kept"
    save_model(m, tmp_path / "model.json")
    before = {n: (tmp_path / n).read_bytes() for n in names}
    res = CliRunner().invoke(main, [stage, *names, "-m", "model.json", *extra],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.stderr
    assert {n: (tmp_path / n).read_bytes() for n in names} == before
    obj = json.loads((tmp_path / "model.json").read_text())
    assert obj["note"] == foreign["note"]
    assert obj["parameters"]["custom_param"]["value"] == foreign["custom_param"]
    stages = {p["stage"] for p in obj["parameters"].values()}
    assert stage in stages
    for v in obj["parameters"].values():
        assert isinstance(v["value"], float | int) and math.isfinite(v["value"])
    assert _no_temp_files(tmp_path)



# ---- report and demo folders -----------------------------------------------------------------

def test_report_reuses_a_folder_and_leaves_other_files(tmp_path, monkeypatch):
    _stage_available("report")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "step.csv").write_bytes((FIX / "paper" / "step_1.0V.csv").read_bytes())
    _model_file(tmp_path / "model.json")
    rep = tmp_path / "rep"
    rep.mkdir()
    (rep / "notes.txt").write_text("my notes\n")
    for _ in range(2):  # a second run replaces its own files
        res = CliRunner().invoke(main, ["report", "step.csv", "-m", "model.json", "-o", "rep"],
                                 catch_exceptions=False)
        assert res.exit_code == 0, res.stderr
    assert (rep / "notes.txt").read_text() == "my notes\n"
    assert json.loads((rep / "metrics.json").read_text())
    assert _no_temp_files(rep)


def test_demo_refuses_a_folder_holding_a_users_model(tmp_path, monkeypatch):
    """Refused up front: if demo starts fitting, the patched stage makes the test fail fast."""
    _stage_available("demo")
    import pmdcid.identify.electrical as electrical

    d = tmp_path / "work"
    d.mkdir()
    mine = b'{"parameters": {"R": {"value": 1.0}}, "effects": [], "note": "my model"}\n'
    (d / "model.json").write_bytes(mine)

    def started(*a, **k):
        raise RuntimeError("demo started work in a folder holding a user's model.json")

    monkeypatch.setattr(electrical, "fit_electrical", started)
    res = CliRunner().invoke(main, ["demo", "-o", str(d)], catch_exceptions=False)
    assert (d / "model.json").read_bytes() == mine
    assert res.exit_code == 1, res.stderr
    assert res.stderr.startswith("error: ") and "internal error" not in res.stderr


# ---- diagnose: MODEL is only read; failed runs leave earlier outputs ------------------------

def test_diagnose_never_changes_model_or_logs(tmp_path, monkeypatch):
    _stage_available("diagnose")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "step.csv").write_bytes((FIX / "hidden" / "step_1.0V.csv").read_bytes())
    old = _model_file(tmp_path / "model.json")
    log = (tmp_path / "step.csv").read_bytes()
    res = CliRunner().invoke(main, ["diagnose", "step.csv", "-m", "model.json", "-o", "new.json",
                                    "--summary", "sum.json"], catch_exceptions=False)
    assert res.exit_code == 0, res.stderr
    assert (tmp_path / "model.json").read_bytes() == old
    assert (tmp_path / "step.csv").read_bytes() == log
    load_model(tmp_path / "new.json").require(*PAPER)  # a complete, valid model file
    summary = json.loads((tmp_path / "sum.json").read_text())
    assert {"added", "candidates", "before", "after", "unexplained"} <= set(summary)
    assert _no_temp_files(tmp_path)


def test_failed_diagnose_keeps_earlier_outputs(tmp_path, monkeypatch):
    _stage_available("diagnose")
    monkeypatch.chdir(tmp_path)
    (tmp_path / "bad.csv").write_text("t,v,i,omega,theta\n")
    _model_file(tmp_path / "model.json")
    earlier = {"new.json": b'{"parameters": {}, "effects": [], "note": "earlier"}\n',
               "sum.json": b'{"added": ["stribeck"]}\n'}
    for name, data in earlier.items():
        (tmp_path / name).write_bytes(data)
    res = CliRunner().invoke(main, ["diagnose", "bad.csv", "-m", "model.json", "-o", "new.json",
                                    "--summary", "sum.json"], catch_exceptions=False)
    assert res.exit_code == 1 and res.stderr.startswith("error: bad.csv: ")
    assert {n: (tmp_path / n).read_bytes() for n in earlier} == earlier
    assert _no_temp_files(tmp_path)
