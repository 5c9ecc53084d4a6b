"""A parameter the logs only bound (issue #24, honest uncertainty): written as an interval, never
as a standard error — in the model file (``interval``, ``stderr`` null), in every table, and
it never overwrites what other data determined."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from ident_util import step_logs
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.io.logs import write_log
from pmdcid.model import Model, load_model
from pmdcid.synth import PAPER

FIX = FIXTURES


def _single_step(tmp_path, vals, seed: int) -> Path:
    """One 2 V step from rest, paper noise: the rotor's torque passes the dead zone once, while
    the Coulomb friction (above dz) still holds it: the dead zone is not identifiable."""
    (lg,) = step_logs(vals, np.random.default_rng(seed), amplitudes=(2.0,))
    path = tmp_path / "step.csv"
    write_log(path, lg.t, {c: lg[c] for c in ("v", "omega")})
    return path


def test_single_step_writes_the_dead_zone_as_an_interval(tmp_path, monkeypatch, paper_values):
    monkeypatch.chdir(tmp_path)
    vals = {**paper_values, "dz": 0.6 * PAPER["bc"]}
    _single_step(tmp_path, vals, 7)
    start = Model()
    for k in ("R", "L", "km", "J", "bv", "bc"):
        start.set(k, vals[k] * (1.1 if k in ("J", "bc") else 1.0), stage="start")
    start.save(tmp_path / "m.json")
    run = CliRunner().invoke
    r = run(main, ["fit-nonlinear", "step.csv", "-m", "m.json"], catch_exceptions=False)
    assert r.exit_code == 0, r.output
    dz = json.loads((tmp_path / "m.json").read_text())["parameters"]["dz"]
    lo, hi = dz["interval"]
    assert lo <= vals["dz"] <= hi and lo <= dz["value"] <= hi, dz
    assert dz["stderr"] is None and "record" in dz["caveat"]
    (row,) = [ln for ln in r.output.splitlines() if ln.startswith("dz ")]
    assert f"between {lo:.3g} and {hi:.3g} N m (not identifiable" in row, row
    assert "±" not in row
    # read back: said in words by the model's table, frame and dict; it simulates
    back = load_model(tmp_path / "m.json")
    assert back.parameters["dz"].interval == (lo, hi)
    assert "between" in [ln for ln in str(back).splitlines() if ln.startswith("dz ")][0]
    frame = back.to_pandas().set_index("parameter")
    assert frame.loc["dz", "low"] == lo and frame.loc["dz", "high"] == hi
    assert math.isnan(frame.loc["dz", "stderr"]) and math.isnan(frame.loc["J", "low"])
    assert "between" in back._repr_html_()
    r = run(main, ["simulate", "step.csv", "-m", "m.json", "-o", "sim.csv"],
            catch_exceptions=False)
    assert r.exit_code == 0, r.output
    assert (tmp_path / "sim.csv").stat().st_size > 0


def test_a_bound_keeps_what_other_data_determined():
    m = Model()
    m.set("dz", 0.003, 0.0002, stage="fit-nonlinear")
    assert not m.set_bounded("dz", 0.0, 0.008, stage="joint fit")  # inside: kept
    assert m.parameters["dz"].stderr == 0.0002 and m.parameters["dz"].interval is None
    assert m.set_bounded("dz", 0.0, 0.002, stage="joint fit")  # these logs exclude it
    assert m.parameters["dz"].interval == (0.0, 0.002) and m.value("dz") == 0.001
    m.set("dz", 0.003, stage="start")  # a start value is no determination
    assert m.set_bounded("dz", 0.0, 0.008) and m.value("dz") == 0.004


def test_a_fit_that_only_bounds_dz_keeps_the_models_determined_one(rng, paper_values):
    """fit-nonlinear on one step cannot see the dead zone; the model's own dz (determined by
    other logs, here the truth with a 5 % error) lies in the interval: apply keeps it and its
    error, and writes the others."""
    from pmdcid.identify.nonlinear import fit_nonlinear

    vals = {**paper_values, "dz": 0.6 * PAPER["bc"]}
    logs = step_logs(vals, rng, amplitudes=(2.0,))
    m = Model()
    for k in ("R", "L", "km", "J", "bv", "bc"):
        m.set(k, vals[k] * (1.1 if k in ("J", "bc") else 1.0), stage="start")
    m.set("dz", vals["dz"], 0.05 * vals["dz"], stage="fit-nonlinear (triangles)")
    res = fit_nonlinear(logs, m, priors=False)
    lo, hi = res.estimates["dz"].interval
    assert lo <= vals["dz"] <= hi
    res.apply(m)
    dz = m.parameters["dz"]
    assert (dz.value, dz.stderr, dz.stage) == (vals["dz"], 0.05 * vals["dz"],
                                              "fit-nonlinear (triangles)")
    assert m.parameters["J"].stage == "fit-nonlinear"


@pytest.mark.parametrize("entry, says", [
    ('{"value": 0.004, "interval": [0.0]}', "give two numbers"),
    ('{"value": 0.004, "interval": [0.0, "0.008"]}', "give two numbers"),
    ('{"value": 0.004, "interval": [0.008, 0.0]}', "low <= high"),
    ('{"value": 0.004, "interval": [0.0, 1e300]}', "low <= high"),
    ('{"value": 0.009, "interval": [0.0, 0.008]}', "outside its interval"),
    ('{"value": 0.004, "stderr": 0.001, "interval": [0.0, 0.008]}', "both a stderr"),
    ('{"value": 0.004, "interval": [0.0, 0.008], "caveat": 3}', "a caveat is a text"),
], ids=["one", "text", "reversed", "beyond-bounds", "value-outside", "with-stderr", "caveat"])
def test_a_malformed_interval_is_one_clear_line(tmp_path, monkeypatch, entry, says):
    monkeypatch.chdir(tmp_path)
    truth = json.loads((FIX / "paper" / "truth.json").read_text())
    truth["parameters"]["dz"] = json.loads(entry)
    (tmp_path / "m.json").write_text(json.dumps(truth))
    shutil.copy(FIX / "paper" / "step_1.5V.csv", tmp_path / "step.csv")
    r = CliRunner().invoke(main, ["simulate", "step.csv", "-m", "m.json", "-o", "o.csv"],
                           catch_exceptions=False)
    assert r.exit_code == 1, r.output
    assert says in r.stderr and "m.json" in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "'dz'" in r.stderr


def test_an_interval_in_a_prefixed_unit_is_scaled_like_the_value(tmp_path):
    p = tmp_path / "m.json"
    p.write_text('{"parameters": {"dz": {"value": 4, "unit": "mN m", "interval": [0, 8]}}}')
    par = load_model(p).parameters["dz"]
    assert par.value == pytest.approx(0.004) and par.interval == pytest.approx((0.0, 0.008))
