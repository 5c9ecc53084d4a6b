"""Small seams a user falls through between commands (issue #26, item 6)."""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import REPO

from pmdcid.cli import main

REPO = REPO


@pytest.mark.parametrize("command, written", [("simulate", False), ("export", False),
                                              ("report", False), ("diagnose", False),
                                              ("fit-electrical", True), ("identify", True)])
def test_model_option_help_says_whether_the_model_is_written(command, written):
    out = CliRunner().invoke(main, [command, "--help"]).output
    help_m = " ".join(out.split("-m, --model MODEL", 1)[1].split("\n  -", 1)[0].split())
    assert ("read and updated" in help_m) == written, help_m
    assert ("read only" in help_m) == (not written), help_m


def _paragraphs(md: str) -> list[str]:
    return [" ".join(p.split()) for p in re.split(r"\n\s*\n", md)]


def test_cli_md_says_what_make_demo_runs():
    make = (REPO / "Makefile").read_text()
    recipe = make.split("\ndemo:", 1)[1].split("\n\n", 1)[0]
    command = re.search(r"\$\(PMDCID\) (\S+)", recipe).group(1)
    mentions = [p for p in _paragraphs((REPO / "docs" / "cli.md").read_text())
                if "`make demo`" in p]
    assert mentions
    for p in mentions:
        assert f"pmdcid {command}" in p, p


def test_a_mapping_without_speed_names_the_file_and_what_to_map(tmp_path):
    t = np.arange(2000) * 1e-3
    v = np.where(t > 0.2, 2.0, 0.0)
    rpm = np.where(t > 0.2, 300.0 * (1 - np.exp(-(t - 0.2) / 0.1)), 0.0)
    path = tmp_path / "bench.csv"
    path.write_text("time,volts,rpm_sensor\n" + "\n".join(
        f"{a:.4f},{b:.3f},{c:.3f}" for a, b, c in zip(t, v, rpm, strict=True)) + "\n")
    r = CliRunner().invoke(main, ["identify", str(path), "-m", str(tmp_path / "m.json"),
                                  "-c", "t=time", "-c", "v=volts"])
    assert r.exit_code == 1
    (line,) = r.stderr.strip().splitlines()
    assert line.startswith("error: no log identifies anything")
    assert str(path) in line and "measures no speed, angle or current" in line
    assert "rpm_sensor" in line and "-c omega=rpm_sensor*SCALE" in line
    assert not (tmp_path / "m.json").exists()
