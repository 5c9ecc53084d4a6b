"""`pmdcid demo`: the whole pipeline on fixtures/hidden, end to end."""

import json
import re
from pathlib import Path

import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.demo import DATA_ENV, demo_data_dir, run_demo

FIX = FIXTURES
TRUTH = json.loads((FIX / "hidden" / "truth.json").read_text())


@pytest.mark.slow
def test_demo_end_to_end(tmp_path):
    lines: list[str] = []
    res = run_demo(tmp_path / "d", echo=lines.append)
    text = "\n".join(lines)
    out = tmp_path / "d"
    # progress for every stage, the parameter table, the report path
    n = len(res["times"])
    assert [int(k) for k in re.findall(r"^\[(\d)/\d\]", text, re.M)] == list(range(1, n + 1))
    assert "parameter" in text and f"Report: {res['report']}" in text
    assert Path(res["report"]).is_file() and Path(res["metrics"]).is_file()
    fitted = json.loads((out / "model.json").read_text())["parameters"]
    truth = TRUTH["parameters"]
    # the three fits on the stribeck-carrying logs: R, L from blocked rotor, km as given
    assert fitted["R"]["value"] == pytest.approx(truth["R"], rel=0.01)
    assert fitted["L"]["value"] == pytest.approx(truth["L"], rel=0.03)
    assert fitted["km"]["value"] == truth["km"]
    metrics = json.loads(Path(res["metrics"]).read_text())
    if res["summary"] is not None:  # diagnose exists: it names the hidden effect and helps
        s = res["summary"]
        assert "stribeck" in s["added"]
        assert s["after"]["omega_nrmse"] < 0.5 * s["before"]["omega_nrmse"]
        final = res["model"]
        for p in ("J", "bv", "bc", "fs"):
            assert final.value(p) == pytest.approx(truth[p], rel=0.05), p
        assert "What the loop found: added" in text
        ba = metrics["before_after"]
        assert ba["mean_after"]["omega_nrmse"] < ba["mean_before"]["omega_nrmse"]
        assert metrics["summary"]["added"] == s["added"]
    # the report shows the model on the triangle within a few % of the measurement
    tri = next(lg for lg in metrics["logs"] if lg["name"] == "triangle")
    assert tri["signals"]["omega"]["fit_percent"] > 90


def test_demo_data_dir_env(tmp_path, monkeypatch):
    monkeypatch.delenv(DATA_ENV, raising=False)
    assert (demo_data_dir() / "triangle.csv").is_file()
    monkeypatch.setenv(DATA_ENV, str(tmp_path))
    r = CliRunner().invoke(main, ["demo", "-o", str(tmp_path / "d")])
    assert r.exit_code == 1
    assert DATA_ENV in r.output and str(tmp_path) in r.output
    assert not (tmp_path / "d").exists()
