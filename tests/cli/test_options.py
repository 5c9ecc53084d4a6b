"""pmdcid/cli/options.py: what the shared options and argument types make of bad values. A file
a command reads that is a folder, missing or unreadable is a file problem (exit 1, one line
naming it), never click's usage message; a ``-c`` mapping that does not parse is a usage error
(exit 2), whether it fails at once or only against the log's names."""

from __future__ import annotations

import errno
import os
import shutil

import pytest
from click.testing import CliRunner

import pmdcid.io.csvsource
from pmdcid.cli import main

COMMANDS = {  # a command reading each kind of file, the file's place in its arguments
    "fit-electrical": ["fit-electrical", "{f}", "-m", "m.json"],
    "identify": ["identify", "{f}", "-m", "m.json"],
    "report": ["report", "{f}", "-m", "m.json", "-o", "rep"],
    "simulate": ["simulate", "{f}", "-m", "m.json", "-o", "out.csv"],
    "diagnose": ["diagnose", "{f}", "-m", "m.json", "-o", "new.json"],
    "plan --check": ["plan", "--check", "{f}", "-m", "m.json"],
    "channels": ["channels", "{f}"],
    "-m MODEL": ["simulate", "step.csv", "-m", "{f}", "-o", "out.csv"],
    "--map": ["fit-electrical", "step.csv", "-m", "m.json", "--map", "{f}"],
    "--before": ["report", "step.csv", "-m", "m.json", "-o", "rep", "--before", "{f}"],
    "fleet MANIFEST": ["fleet", "{f}", "-o", "fl"],
}


def _one_error(res, *words) -> str:
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert lines[0].startswith("error: ") and all(w in lines[0] for w in words), lines[0]
    return lines[0]


@pytest.mark.parametrize("args", COMMANDS.values(), ids=COMMANDS.keys())
def test_a_folder_given_as_a_file_is_exit_1(paper_step, args):
    """A LOG that is a folder was click's 3-line usage message and exit 2; a missing one exit 1."""
    (paper_step / "adir").mkdir()
    res = CliRunner().invoke(main, [a.format(f="adir") for a in args])
    line = _one_error(res, "error: adir: ")
    assert "folder" in line or "Is a directory" in line, line


def test_an_unreadable_log_is_exit_1(paper_step, monkeypatch):
    shutil.copy(paper_step / "step.csv", paper_step / "noperm.csv")
    if os.geteuid() != 0:
        os.chmod(paper_step / "noperm.csv", 0)
    else:  # root reads anything: the file is unreadable to click's check and to the reader
        access, real_open = os.access, open

        def denied(path, *args, **kwargs):
            if os.fspath(path).endswith("noperm.csv"):
                raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), path)
            return real_open(path, *args, **kwargs)

        monkeypatch.setattr(os, "access", lambda p, mode, **kw: not os.fspath(p).endswith(
            "noperm.csv") and access(p, mode, **kw))
        monkeypatch.setattr(pmdcid.io.csvsource, "open", denied, raising=False)
    res = CliRunner().invoke(main, ["fit-electrical", "noperm.csv", "-m", "m.json"])
    _one_error(res, "noperm.csv", "Permission denied")


@pytest.mark.parametrize("spec", ["v=v*12/255-", "v=v*2**3", "omega=omega*-rpm",
                                  "v=v*12/255+1e", "v=v*12/0"])
def test_a_malformed_column_mapping_is_a_usage_error(paper_step, spec):
    """-c v=pwm*12/255- was exit 1 (its '/' kept it for the log's signal names), -c v=pwm*2**3
    exit 2: every malformed -c is exit 2 now, its value and what is wrong on the Error line."""
    res = CliRunner().invoke(main, ["fit-mechanical", "step.csv", "-m", "m.json", "-c", spec])
    assert res.exit_code == 2, res.output
    error = res.stderr.strip().splitlines()[-1]
    assert error.startswith("Error: Invalid value for '-c' / '--column': column mapping "
                            f"'{spec}'"), error
    assert "step.csv" not in error


def test_a_mapping_naming_an_absent_column_stays_exit_1(paper_step):
    res = CliRunner().invoke(main, ["fit-mechanical", "step.csv", "-m", "m.json",
                                    "-c", "omega=speed_rpm*rpm"])
    _one_error(res, "step.csv", "no column 'speed_rpm'")


@pytest.mark.parametrize("command", ["fit-mechanical", "identify"])
@pytest.mark.parametrize("km, said", [("1e-300", "is below 1e-09, the smallest value"),
                                      ("1e300", "is above 1000, the largest value")])
def test_a_km_outside_the_models_bounds_is_a_usage_error(paper_step, command, km, said):
    """fuzz: --km 1e-300 passed fit-mechanical's option and failed as 'the fit gives parameter
    km = 1e-300 ... the logs do not behave as this motor model's'; identify took 1e300 and
    blamed the log's speed. Both bounds are the model's, said at the option (exit 2), every
    command that takes --km."""
    res = CliRunner().invoke(main, [command, "step.csv", "-m", "m.json", "--km", km])
    assert res.exit_code == 2, res.stderr
    assert "Invalid value for '--km'" in res.stderr and said in res.stderr, res.stderr
    assert "Traceback" not in res.stderr


def test_an_output_a_log_pattern_matches_is_refused_before_any_work(tmp_path):
    """``diagnose "logs/*.csv" -o logs/old.csv`` from a shell that passes the pattern as written:
    the guard compares the output with the files the pattern matches, so the user's log
    old.csv is not overwritten by the new model (before, the guard saw only the pattern and the
    command read old.csv as a log, then wrote its model over it)."""
    from pathlib import Path

    paper = Path(__file__).resolve().parents[2] / "fixtures" / "paper"
    logs = tmp_path / "logs"
    logs.mkdir()
    for name in ("step_1.0V.csv", "step_2.0V.csv"):
        shutil.copy(paper / name, logs / name)
    shutil.copy(paper / "truth.json", tmp_path / "m.json")
    before = (logs / "step_2.0V.csv").read_bytes()
    res = CliRunner().invoke(main, ["diagnose", str(logs / "*.csv"), "-m", str(tmp_path / "m.json"),
                                    "-o", str(logs / "step_2.0V.csv")])
    _one_error(res, "output would overwrite the input")
    assert (logs / "step_2.0V.csv").read_bytes() == before
