"""pmdcid/fleet/run.py: ``fleet -o DIR`` replaces units.parquet, outliers.csv and fleet.html
only where a fleet wrote them; anything else under those names is refused before any work
unless ``--force``."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner

from pmdcid.cli import main

pytest.importorskip("pyarrow.parquet")
FIX = Path(__file__).resolve().parents[2] / "fixtures" / "paper"


@pytest.mark.parametrize("name", ["outliers.csv", "fleet.html", "units.parquet"])
def test_fleet_keeps_a_file_it_did_not_write(tmp_path, name):
    shutil.copy(FIX / "step_1.5V.csv", tmp_path / "a.csv")
    (tmp_path / "m.csv").write_text("unit,log\nu1,a.csv\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / name).write_text("unit,my own notes\n")
    res = CliRunner().invoke(main, ["fleet", str(tmp_path / "m.csv"), "-o", str(out)])
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert f"{name}: exists and was not written by pmdcid" in lines[0]
    assert (out / name).read_text() == "unit,my own notes\n"
    assert sorted(p.name for p in out.iterdir()) == [name]  # no journal: before any work
