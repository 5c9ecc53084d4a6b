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


def test_a_fleet_whose_every_unit_fails_keeps_its_record_and_exits_1(tmp_path):
    """Nothing could be identified: units.parquet, outliers.csv and fleet.html still say why
    (written and kept), and the command exits 1 with one line naming the first failure; a rerun
    on DIR resumes every unit from the journal (no cluster) and says the same, and the API
    raises the library's error with the result attached."""
    pytest.importorskip("distributed")
    import pyarrow.parquet as pq

    from pmdcid import api
    from pmdcid.fleet.run import FleetError

    (tmp_path / "a.csv").write_text("t,v\n0,1\n0.001,x\n")
    (tmp_path / "b.csv").write_text("t,v\n0,1\n0.001,2\n")
    (tmp_path / "m.csv").write_text("unit,log\nu1,a.csv\nu2,b.csv\n")
    out = tmp_path / "out"
    res = CliRunner().invoke(main, ["fleet", str(tmp_path / "m.csv"), "-o", str(out),
                                    "--workers", "1", "--no-diagnose"])
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.output
    assert lines[0].startswith("error: no unit could be identified: all 2 failed ("), lines
    assert "(units.parquet says why); first: u1: " in lines[0] and "a.csv: column 'v'" in lines[0]
    assert "0 identified, 2 failed" in res.stdout
    assert {"units.parquet", "outliers.csv", "fleet.html"} <= {p.name for p in out.iterdir()}
    rows = pq.read_table(out / "units.parquet").to_pylist()
    assert [(r["unit"], r["status"]) for r in rows] == [("u1", "error"), ("u2", "error")]

    with pytest.raises(FleetError, match="no unit could be identified: all 2 failed") as err:
        api.run_fleet(str(tmp_path / "m.csv"), str(out), diagnose=False)
    assert err.value.result.resumed == 2 and err.value.result.ran == 0
    assert [r["status"] for r in err.value.result.rows] == ["error", "error"]
