"""Warnings and notes are data (issue #26): a :class:`~pmdcid.notes.Note` carries its text, what
it concerns and its severity; the stages' results give them (``all_notes()``, ``to_dict()``),
the CLI prints warnings on stderr and notes on stdout, the model file keeps them."""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

import pmdcid
from pmdcid.cli import main
from pmdcid.io.logs import write_log
from pmdcid.notes import Note, as_note, to_records

PAPER_DIR = FIXTURES / "paper"
NAMES = ("dz", "bc", "L", "R", "sensor_delay", "delay")


def test_a_note_is_its_text_and_knows_what_it_concerns():
    n = Note("dz is not identifiable from these logs: any dead zone fits", about="dz")
    assert n == "dz is not identifiable from these logs: any dead zone fits"
    assert pmdcid.Note is Note
    assert "identifiable" in n and n.about == ("dz",) and n.severity == "warning"
    back = pickle.loads(pickle.dumps(n.in_stage("fit-nonlinear")))
    assert back.about == ("dz",) and back.stage == "fit-nonlinear"
    assert str(back).startswith("fit-nonlinear: dz is")
    assert as_note(back.to_dict()).to_dict() == back.to_dict()
    with pytest.raises(ValueError):
        Note("x", severity="fatal")


@pytest.mark.parametrize("text, about, log", [
    ("dz is not identifiable from these logs: any dead zone from 0 to 8 mN m fits", ("dz",), ""),
    ("reduced chi-square 10.3 >> 1: the model leaves structure (dz, bc)", (), ""),
    ("bc and dz are strongly correlated (+0.97): the logs hardly tell them apart",
     ("dz", "bc"), ""),
    ("L = 0.0178 ± 0.02 H is poorly determined: sample faster", ("L",), ""),
    ("sensor_delay = 3.2 ms with no current logged: a command applied late looks the same",
     ("sensor_delay",), ""),
    ("a/b.csv: tau_e = 0.4 ms is under 2 sample periods: L is not identifiable", (), "a/b.csv"),
])
def test_a_plain_message_is_read_by_one_rule(text, about, log):
    n = as_note(text, names=NAMES, logs=["a/b.csv"])
    assert set(n.about) == set(about) and n.log == log and str(n) == text


def _speed_only_step(tmp_path) -> Path:
    lg = pmdcid.Log.from_csv(PAPER_DIR / "step_2.0V.csv")
    path = tmp_path / "step.csv"
    write_log(path, lg.t, {"v": lg["v"], "omega": lg["omega"]}, {"kind": "free-speed-step"})
    return path


def test_a_lumped_fit_says_so_as_a_note_the_api_and_the_model_file_keep(tmp_path):
    step = _speed_only_step(tmp_path)
    res = pmdcid.fit_mechanical(step, None)
    notes = res.all_notes()
    lumped = [n for n in notes if n.startswith("lumped model: per-volt")]
    assert len(lumped) == 1 and lumped[0].severity == "note"
    assert lumped[0].stage == "fit-mechanical"
    assert all(n.severity == "warning" for n in notes if n not in lumped)
    assert res.to_dict()["notes"][0]["severity"] == "note"

    model = tmp_path / "m.json"
    for _ in range(2):  # run twice: the stage's notes are replaced, not added again
        r = CliRunner().invoke(main, ["fit-mechanical", str(step), "-m", str(model)])
        assert r.exit_code == 0, r.output
    assert "note: lumped model: per-volt" in r.stdout
    assert "note:" not in r.stderr
    assert all(ln.startswith("warning: ") for ln in r.stderr.splitlines())
    kept = json.loads(model.read_text())["notes"]
    assert [k["text"] for k in kept] == [str(n) for n in notes]
    assert {k["stage"] for k in kept} == {"fit-mechanical"}


def test_identify_result_gathers_every_stage_and_its_own_notes():
    from pmdcid.pipeline import IdentifyResult, LogPlan

    res = IdentifyResult(pmdcid.Model(), [LogPlan("x.csv", "rich", "ramp")])
    res.warnings.append(Note("dz is not identifiable", "dz").in_stage("joint fit"))
    res.warnings.append("joint fit: reduced chi-square 10.3 >> 1: the model leaves structure")
    res.notes.append("no km: the mechanical part is identified per volt (lumped); give --km")
    got = res.all_notes()
    assert [n.severity for n in got] == ["warning", "warning", "note"]
    assert got[0].about == ("dz",) and got[0].stage == "joint fit"
    assert got[2].stage == "identify"
    model = pmdcid.Model()
    res.record_notes(model)
    assert to_records(got) == model.extra["notes"]
    assert json.loads(json.dumps(model.extra["notes"])) == model.extra["notes"]


def test_notes_survive_a_model_file_round_trip(tmp_path):
    m = pmdcid.Model()
    m.set("dz", 0.004, 0.0023)
    m.extra["notes"] = to_records([Note("dz is not identifiable", "dz", stage="fit-nonlinear")])
    m.save(tmp_path / "m.json")
    back = pmdcid.Model.load(tmp_path / "m.json")
    (n,) = [as_note(r) for r in back.extra["notes"]]
    assert n.about == ("dz",) and n.stage == "fit-nonlinear" and isinstance(n, str)
    assert np.isclose(back.value("dz"), 0.004)


@pytest.mark.slow
def test_identify_prints_notes_keeps_them_and_the_report_shows_the_dz_caveat(tmp_path):
    """End to end on voltage + speed steps: the lumped note on stdout, the dead zone's caveat
    as a warning, both in the model file, and the dz row of the report says why."""
    paths = []
    for amp in ("1.0", "2.0"):
        lg = pmdcid.Log.from_csv(PAPER_DIR / f"step_{amp}V.csv")
        paths.append(tmp_path / f"step_{amp}.csv")
        write_log(paths[-1], lg.t, {"v": lg["v"], "omega": lg["omega"]},
                  {"kind": "free-speed-step"})
    model = tmp_path / "m.json"
    r = CliRunner().invoke(main, ["identify", *map(str, paths), "-m", str(model),
                                  "--no-diagnose"])
    assert r.exit_code == 0, r.output
    assert "note: fit-mechanical: lumped model: per-volt" in r.stdout
    assert all(ln.startswith("warning: ") for ln in r.stderr.splitlines())
    kept = json.loads(model.read_text())["notes"]
    (dz,) = [k for k in kept if "dz is not identifiable" in k["text"]]
    assert dz["about"] == ["dz"] and dz["severity"] == "warning"
    assert {k["severity"] for k in kept if "lumped model: per-volt" in k["text"]} == {"note"}
    r = CliRunner().invoke(main, ["report", str(paths[0]), "-m", str(model),
                                  "-o", str(tmp_path / "rep")])
    assert r.exit_code == 0, r.output
    page = (tmp_path / "rep" / "report.html").read_text()
    row = page.split("id='param-dz'", 1)[1].split("</tr>", 1)[0]
    assert "dz is not identifiable from these logs" in row
