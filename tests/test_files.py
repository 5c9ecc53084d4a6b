"""The one front door over the one files layer (issue #25): a command and the api function it
calls write the same files; the lumped path is written once (mark, fit, relabel, mark again);
the output-is-an-input guard answers by file, not by name."""

from __future__ import annotations

import json
import os
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import pmdcid
from pmdcid import api
from pmdcid.cli import main
from pmdcid.errors import LogError
from pmdcid.identify.runners import apply_stage, fit_stage, stage_mechanical
from pmdcid.io.logs import write_log
from pmdcid.model.lumped import is_lumped
from pmdcid.runtime.outputs import input_at, same_file

PAPER_DIR = Path(__file__).resolve().parents[1] / "fixtures" / "paper"


def _params(path) -> dict:
    return {k: v["value"] for k, v in json.loads(Path(path).read_text())["parameters"].items()}


def test_a_fit_command_writes_what_its_api_function_writes(tmp_path):
    shutil.copy(PAPER_DIR / "blocked_1.5V.csv", tmp_path / "b.csv")
    for name in ("cli.json", "api.json"):
        shutil.copy(PAPER_DIR / "truth.json", tmp_path / name)
    out = CliRunner().invoke(main, ["fit-electrical", str(tmp_path / "b.csv"), "-m",
                                    str(tmp_path / "cli.json")])
    assert out.exit_code == 0, out.output
    res = api.fit_electrical(str(tmp_path / "b.csv"), str(tmp_path / "api.json"), update=True)
    assert _params(tmp_path / "api.json") == _params(tmp_path / "cli.json")
    assert _params(tmp_path / "api.json")["R"] == res.estimates["R"].value
    # without update the model file is only read
    before = (tmp_path / "api.json").read_bytes()
    api.fit_electrical(str(tmp_path / "b.csv"), str(tmp_path / "api.json"))
    assert (tmp_path / "api.json").read_bytes() == before


def test_the_lumped_path_marks_fits_relabels_and_marks_again(tmp_path):
    lg = pmdcid.Log.from_csv(PAPER_DIR / "step_1.0V.csv")
    write_log(tmp_path / "s.csv", lg.t, {"v": lg["v"], "omega": lg["omega"]})  # no current
    logs = [pmdcid.Log.from_csv(tmp_path / "s.csv")]
    given = pmdcid.Model()
    res = fit_stage(stage_mechanical, logs, given)
    assert not is_lumped(given) and not given.parameters  # the model given is not touched
    assert res.lumped and res.estimates["J"].unit == "V s^2/rad"
    fresh = pmdcid.Model()  # e.g. the model file re-read under the lock
    apply_stage(res, fresh)
    assert is_lumped(fresh) and fresh.parameters["bc"].unit == "V"


def test_input_at_compares_files_not_names(tmp_path):
    log = tmp_path / "log.csv"
    log.write_text("t,v\n0,0\n")
    os.link(log, tmp_path / "hard.csv")
    (tmp_path / "soft.csv").symlink_to(log)
    other = tmp_path / "other.csv"
    other.write_text("t,v\n0,0\n")
    assert input_at(tmp_path / "hard.csv", [str(other), str(log)]) == str(log)
    assert input_at(tmp_path / "soft.csv", [str(log)]) == str(log)
    assert input_at(other, [str(log)]) is None
    new = tmp_path / "new.json"  # not written yet: the same path only when planned
    assert not same_file(new, new) and same_file(new, tmp_path / "." / "new.json", planned=True)


def test_file_options_go_with_the_file(tmp_path):
    with pytest.raises(TypeError, match="out_dir"):
        api.identify(str(PAPER_DIR / "step_1.0V.csv"), None, out_dir=tmp_path / "rep")
    with pytest.raises(TypeError, match="summary"):
        api.diagnose(str(PAPER_DIR / "step_1.0V.csv"), str(PAPER_DIR / "truth.json"),
                     summary=tmp_path / "s.json")
    with pytest.raises(TypeError, match="model"):
        api.fit_electrical(str(PAPER_DIR / "blocked_1.5V.csv"), pmdcid.Model(), update=True)
    assert not list(tmp_path.iterdir())


def test_identify_refuses_a_report_file_it_did_not_write_before_any_work(tmp_path, monkeypatch):
    """identify -o DIR: a report.html pmdcid did not write was refused only after the whole
    identification; now before it, and --force (identify's) replaces it."""
    import pmdcid.pipeline

    def no_work(*args, **kwargs):
        raise AssertionError("identify ran before its outputs were checked")

    monkeypatch.setattr(pmdcid.pipeline, "identify", no_work)
    (tmp_path / "rep").mkdir()
    (tmp_path / "rep" / "report.html").write_text("<html>mine</html>")
    res = CliRunner().invoke(main, ["identify", str(PAPER_DIR / "step_1.0V.csv"), "-m",
                                    str(tmp_path / "m.json"), "-o", str(tmp_path / "rep")])
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert "report.html: exists and was not written by pmdcid" in lines[0]
    assert (tmp_path / "rep" / "report.html").read_text() == "<html>mine</html>"
    assert not (tmp_path / "m.json").exists()


def test_simulate_into_a_folder_checks_every_output_first(tmp_path):
    from pmdcid.files import simulate_files

    ins = [str(PAPER_DIR / "step_1.0V.csv"), str(PAPER_DIR / "step_2.0V.csv")]
    out = tmp_path / "sims"
    out.mkdir()
    (out / "step_2.0V.csv").write_text("t,v\n0,1\n")  # the user's own file
    with pytest.raises(LogError, match="step_2.0V.csv: exists and was not written"):
        simulate_files(ins, str(PAPER_DIR / "truth.json"), str(out))
    assert sorted(p.name for p in out.iterdir()) == ["step_2.0V.csv"]  # step_1.0V not written
    twice = [ins[0], str(tmp_path / "step_1.0V.csv")]
    shutil.copy(ins[0], twice[1])
    with pytest.raises(LogError, match="two INPUTs are named step_1.0V.csv"):
        simulate_files(twice, str(PAPER_DIR / "truth.json"), str(out))


def test_simulate_says_when_the_inputs_time_looks_like_milliseconds(tmp_path):
    """simulate has no plausibility gate: an input whose t is in ms (a sample period of 1) ran
    a thousand times too long with exit 0 and no word; it now runs with one warning naming the
    unit the fit commands name, and the input's time as the fit commands read it."""
    from pmdcid.errors import PmdcidWarning
    from pmdcid.files import simulate_file

    t = np.arange(3000.0)
    write_log(tmp_path / "ms.csv", t, {"v": np.where(t > 500, 1.0, 0.0)})
    with pytest.warns(PmdcidWarning, match=r"t looks like milliseconds .*simulated with t as it "
                                           r"stands, in seconds"):
        simulate_file(str(tmp_path / "ms.csv"), str(PAPER_DIR / "truth.json"),
                      str(tmp_path / "out.csv"))
    write_log(tmp_path / "s.csv", t * 1e-3, {"v": np.where(t > 500, 1.0, 0.0)})
    with warnings.catch_warnings():
        warnings.simplefilter("error", PmdcidWarning)
        simulate_file(str(tmp_path / "s.csv"), str(PAPER_DIR / "truth.json"),
                      str(tmp_path / "out_s.csv"))


@pytest.mark.parametrize("second", ["./step.csv", "step.csv", "copy.csv"],
                         ids=["another-name", "same-name", "a-copy"])
@pytest.mark.parametrize("command", [["fit-mechanical", "--km", "0.05"], ["identify"],
                                     ["report", "-o", "rep"]])
def test_a_log_given_twice_is_refused(paper_step, second, command):
    """identify log1.csv log1.csv (or ./log1.csv, or a copy) counted the data twice: standard
    errors too small by sqrt(2). Refused in the one place every command reads its logs."""
    shutil.copy(paper_step / "step.csv", paper_step / "copy.csv")
    before = (paper_step / "m.json").read_bytes()
    res = CliRunner().invoke(main, [command[0], "step.csv", second, "-m", "m.json",
                                    *command[1:]])
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert lines[0].startswith(f"error: {second}: ") and "give each log once" in lines[0]
    assert "step.csv" in lines[0].split(": ", 2)[2] or second == "step.csv"
    assert (paper_step / "m.json").read_bytes() == before


def test_the_same_log_object_twice_is_refused():
    lg = pmdcid.Log.from_csv(PAPER_DIR / "step_1.0V.csv")
    with pytest.raises(LogError, match="given twice"):
        api.fit_mechanical([lg, lg], pmdcid.Model(), km=0.05)
    other = pmdcid.Log.from_csv(PAPER_DIR / "step_2.0V.csv")  # different logs pass the check
    from pmdcid.files import refuse_repeated_logs

    refuse_repeated_logs([lg, other, str(PAPER_DIR / "step_1.0V.csv"),
                          str(PAPER_DIR / "step_2.0V.csv")])


def test_a_pattern_the_shell_did_not_expand_reads_the_files_it_matches(tmp_path):
    """``"blocked_*.csv"`` as written (a notebook, Windows' cmd and PowerShell pass patterns
    unexpanded): before, 'no such log file'; now the files it matches, sorted, exactly as if
    listed. A pattern that matches nothing says so; a file whose name holds '[' is itself."""
    for v in ("1.0", "2.0"):
        shutil.copy(PAPER_DIR / f"blocked_{v}V.csv", tmp_path / f"blocked_{v}V.csv")
    listed = api.fit_electrical(sorted(str(p) for p in tmp_path.glob("blocked_*.csv")))
    by_pattern = api.fit_electrical(str(tmp_path / "blocked_*.csv"))
    assert by_pattern.estimates["R"].value == listed.estimates["R"].value
    assert by_pattern.estimates["L"].value == listed.estimates["L"].value
    out = CliRunner().invoke(main, ["fit-electrical", str(tmp_path / "blocked_*.csv"), "-m",
                                    str(tmp_path / "m.json")])
    assert out.exit_code == 0, out.output
    assert _params(tmp_path / "m.json")["R"] == listed.estimates["R"].value
    with pytest.raises(LogError, match="no log file matches this pattern"):
        api.fit_electrical(str(tmp_path / "step_*.csv"))
    odd = tmp_path / "blocked[1].csv"
    shutil.copy(PAPER_DIR / "blocked_1.0V.csv", odd)
    assert api.fit_electrical(str(odd)).estimates["R"].value > 0
