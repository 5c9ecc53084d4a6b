"""pmdcid/plan/output.py: ``plan -o DIR`` writes only over what pmdcid plan wrote there; a
recorded log named like a profile, the user's own plan.md or check.json is refused before any
work unless ``--force`` (as report's folder is)."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from pmdcid.cli import main
from pmdcid.errors import LogError
from pmdcid.plan.output import check_out_dir

GUESS = ["plan", "--guess", "--vmax", "2", "-o"]
FIX = Path(__file__).resolve().parents[2] / "fixtures" / "paper"


def _plan(*args):
    return CliRunner().invoke(main, [*GUESS, *args])


@pytest.mark.parametrize("name, text", [
    ("01_blocked.csv", (FIX / "blocked_1.5V.csv").read_text()),  # the recorded profile
    ("plan.md", "# Identification plan\n\nmy notes on the rig\n"),
    ("plan.json", '{"profiles": []}\n'),
])
def test_plan_keeps_a_file_it_did_not_write(tmp_path, name, text):
    out = tmp_path / "plan"
    out.mkdir()
    (out / name).write_text(text)
    res = _plan(str(out))
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert f"{name}: exists and was not written by pmdcid" in lines[0] and "--force" in lines[0]
    assert (out / name).read_text() == text
    assert sorted(p.name for p in out.iterdir()) == [name]  # refused before anything is written
    assert _plan(str(out), "--force").exit_code == 0
    assert (out / name).read_text() != text


def test_plan_rewrites_its_own_folder(tmp_path):
    out = tmp_path / "plan"
    assert _plan(str(out)).exit_code == 0
    (out / "mine.csv").write_text("t,v\n0,1\n")  # not a profile's name: left alone
    res = _plan(str(out))
    assert res.exit_code == 0, res.output
    assert (out / "mine.csv").read_text() == "t,v\n0,1\n"


def test_plan_check_keeps_a_check_json_it_did_not_write(tmp_path):
    (tmp_path / "check.json").write_text('{"mine": 1}\n')
    with pytest.raises(LogError, match="check.json: exists and was not written by pmdcid"):
        check_out_dir(tmp_path, ["check.json"])
    check_out_dir(tmp_path, ["check.json"], force=True)
