"""Round three, family 2 (issue 29): the one output guard (pmdcid/runtime/outputs.py):
regular files only, never through a link out of the output folder, never replacing what the
tool did not write, a symlink loop refused, no empty folder left by a failed write."""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

import pmdcid
from pmdcid.cli import main

FIX = FIXTURES
EXE = [sys.executable, "-c", "import sys; from pmdcid.cli import main; sys.exit(main())"]
ROOT = Path(pmdcid.__file__).resolve().parents[1]  # the code under test, for the child


def _invoke(args):
    return CliRunner().invoke(main, args, catch_exceptions=False)


def _one_error(res, pattern: str) -> str:
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.stderr
    assert lines[0].startswith("error: ") and pattern in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("args", [
    ["simulate", "step.csv", "-m", "m.json", "-o", "out.csv", "--force"],
    ["export", "-m", "m.json", "--to", "c", "-o", "out.csv", "--force"],
], ids=["simulate", "export"])
def test_a_fifo_output_is_refused_up_front(paper_step, args):
    """A FIFO output hung the command (it was opened to see who wrote it)."""
    os.mkfifo(paper_step / "out.csv")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([*EXE, *args], cwd=paper_step, capture_output=True, text=True, env=env,
                          timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert "FIFO" in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert (paper_step / "out.csv").is_fifo()


def test_devices_are_never_outputs():
    from pmdcid.errors import LogError
    from pmdcid.runtime.outputs import check_target

    with pytest.raises(LogError, match="character device"):
        check_target("/dev/null")  # -o /dev/null --force must never replace it


def test_report_never_writes_through_a_link_out_of_its_folder(paper_step):
    (paper_step / "rep").mkdir()
    outside = paper_step / "precious.png"
    outside.write_bytes(b"mine")
    (paper_step / "rep" / "step_overlay.png").symlink_to(outside)
    _one_error(_invoke(["report", "step.csv", "-m", "m.json", "-o", "rep"]), "symlink")
    _one_error(_invoke(["report", "step.csv", "-m", "m.json", "-o", "rep", "--force"]),
               "symlink")
    assert outside.read_bytes() == b"mine"
    assert not (paper_step / "rep" / "report.html").exists()


@pytest.mark.parametrize("name", ["report.html", "metrics.json"])
def test_report_keeps_a_file_it_did_not_write(paper_step, name):
    (paper_step / "rep").mkdir()
    (paper_step / "rep" / name).write_text("my notes\n")
    _one_error(_invoke(["report", "step.csv", "-m", "m.json", "-o", "rep"]),
               "not written by pmdcid")
    assert (paper_step / "rep" / name).read_text() == "my notes\n"
    assert sorted(p.name for p in (paper_step / "rep").iterdir()) == [name]
    res = _invoke(["report", "step.csv", "-m", "m.json", "-o", "rep", "--force"])
    assert res.exit_code == 0, res.stderr
    res = _invoke(["report", "step.csv", "-m", "m.json", "-o", "rep"])  # ours now: replaced
    assert res.exit_code == 0, res.stderr


def test_a_model_that_is_a_symlink_loop_is_refused(paper_step):
    shutil.copy(FIX / "paper" / "blocked_1.5V.csv", paper_step / "b.csv")
    (paper_step / "loop1.json").symlink_to("loop2.json")
    (paper_step / "loop2.json").symlink_to("loop1.json")
    _one_error(_invoke(["fit-electrical", "b.csv", "-m", "loop1.json"]), "symlink loop")
    assert (paper_step / "loop1.json").is_symlink() and (paper_step / "loop2.json").is_symlink()


def test_a_full_disk_leaves_no_new_folder(paper_step, monkeypatch):
    """The library's report (outside a command's transaction) on a full disk."""
    import pmdcid
    from pmdcid.errors import PmdcidError
    from pmdcid.io import logs as logs_mod

    def full(fd):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(logs_mod.os, "fsync", full)
    with pytest.raises(PmdcidError, match="No space"):
        pmdcid.report("step.csv", "m.json", "new/sub")
    assert not (paper_step / "new").exists()
