"""The library's front door (docs/api.md): lazy ``import pmdcid``, ``Log`` constructors with the
CLI's checks, ``Model``, the one result protocol, the lumped path shared with the CLI runners,
progress lines on a terminal only, and the executed documentation example."""

from __future__ import annotations

import io
import json
import math
import os
import re
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from repo_paths import REPO

import pmdcid
from pmdcid.errors import LogError, ModelError
from pmdcid.io.logs import write_log

REPO = REPO
PAPER_DIR = REPO / "fixtures" / "paper"


def _truth() -> pmdcid.Model:
    obj = json.loads((PAPER_DIR / "truth.json").read_text())
    m = pmdcid.Model()
    for k, v in obj["parameters"].items():
        m.set(k, v)
    return m


def test_import_is_lazy():
    code = ("import sys, pmdcid; heavy = [m for m in ('numpy', 'pandas', 'scipy', 'pmdcid.api', "
            "'pmdcid.io') if m in sys.modules]; print(heavy); "
            "pmdcid.Log; print('pmdcid.io' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split("\n")
    assert out[0] == "[]"
    assert out[1] == "True"


def _angle_log(rng, n=3000, dt=1e-3):
    t = dt * np.arange(n)
    v = np.where(t > 0.5, 2.0, 0.0)
    theta = np.cumsum(np.where(t > 0.5, 3.0, 0.0)) * dt + 1e-4 * rng.standard_normal(n)
    i = 0.1 * v + 0.01 * rng.standard_normal(n)
    return t, v, i, theta


def test_from_arrays_and_dataframe_equal_read_log(tmp_path, rng):
    t, v, i, theta = _angle_log(rng)
    write_log(tmp_path / "a.csv", t, {"v": v, "i": i, "theta": theta})
    ref = pmdcid.Log.from_csv(tmp_path / "a.csv")
    arr = pmdcid.Log.from_arrays(t, v=v, i=i, theta=theta)
    df = pd.DataFrame({"time_ms": t * 1e3, "v": v, "i": i, "angle_deg": np.degrees(theta)})
    frm = pmdcid.Log.from_dataframe(df, columns={"t": "time_ms*ms", "theta": "angle_deg*deg"})
    assert ref.derived == arr.derived == frm.derived == {"omega"}  # speed derived from angle
    for lg in (arr, frm):
        assert lg.dt == pytest.approx(ref.dt, rel=1e-12)
        for c in ("v", "i", "theta", "omega"):
            # the CSV holds 9 significant digits; the derived speed amplifies that rounding
            np.testing.assert_allclose(lg[c], ref[c], rtol=1e-6, atol=1e-5)
    # the reverse: the angle from the speed
    om = pmdcid.Log.from_arrays(t, v=v, omega=ref["omega"])
    assert om.derived == {"theta"}


def test_from_arrays_applies_the_csv_checks(rng):
    t, v, i, theta = _angle_log(rng, n=500)
    jitter = t + np.where(np.arange(500) % 7 == 3, 3e-4, 0.0)
    with pytest.warns(UserWarning, match="loop-timed samples"):  # resampled, said in one line
        assert pmdcid.Log.from_arrays(jitter, v=v, theta=theta).resampled is not None
    gap = np.delete(t, np.arange(100, 120))
    with pytest.raises(LogError, match="samples missing"):
        pmdcid.Log.from_arrays(gap, v=v[:480], theta=theta[:480])
    bad = theta.copy()
    bad[10:40] = np.nan
    with pytest.raises(LogError, match="too many to fill"):
        pmdcid.Log.from_arrays(t, v=v, theta=bad)
    with pytest.raises(LogError, match="infinite"):
        pmdcid.Log.from_arrays(t, v=np.where(t > 0.2, np.inf, 0.0), theta=theta)
    with pytest.raises(LogError, match="as long as t"):
        pmdcid.Log.from_arrays(t, v=v[:-1], theta=theta)
    few = theta.copy()
    few[5] = np.nan
    with pytest.warns(UserWarning, match="filled 1 NaN"):
        lg = pmdcid.Log.from_arrays(t, v=v, theta=few, name="few")
    assert np.isfinite(lg["theta"]).all() and lg.path == "few"
    with pytest.raises(LogError, match="non-numeric"):
        pmdcid.Log.from_dataframe(pd.DataFrame({"t": t.astype(str), "v": ["x"] * 500}))


def test_model_file_table_and_frame(tmp_path):
    m = _truth()
    m.save(tmp_path / "m.json")
    back = pmdcid.Model.load(tmp_path / "m.json")
    assert back.value("J") == m.value("J")
    df = back.to_pandas()
    assert list(df.columns) == ["parameter", "value", "stderr", "unit", "low", "high", "caveat"]
    assert df.set_index("parameter").loc["R", "unit"] == "ohm"
    assert "J" in str(back) and "kg m^2" in str(back) and "<table>" in back._repr_html_()
    with pytest.raises(ModelError, match="not lumped"):
        back.to_si(km=0.05, R=2.0)


def _step_input(t):
    return np.where((t > 0.2) & (t < 1.2), 2.0, 0.0) + np.where(t > 1.6, -1.5, 0.0)


def test_fit_nonlinear_round_trip_and_protocol(rng):
    truth = _truth()
    t = np.arange(0.0, 2.5, 1e-3)
    v = _step_input(t)
    sim = pmdcid.simulate(pmdcid.Log.from_arrays(t, v=v, name="cmd"), truth)
    log = pmdcid.Log.from_arrays(t, v=v, omega=sim.omega + 0.01 * rng.standard_normal(t.size),
                                 name="noisy")
    start = truth.copy()
    for k in ("J", "bv"):
        start.set(k, 1.3 * truth.value(k))
    res = pmdcid.fit_nonlinear(log, start, free=["J", "bv"], priors=False)
    assert start.value("J") == pytest.approx(1.3 * truth.value("J"))  # not modified
    for k in ("J", "bv"):  # within 2 % and 5 standard errors of the truth
        e = res.estimates[k]
        assert e.value == pytest.approx(truth.value(k), rel=0.02)
        assert abs(e.value - truth.value(k)) < 5 * e.stderr
    assert str(res) == res.table()
    df = res.to_pandas().set_index("parameter")
    assert df.loc["J", "value"] == res.estimates["J"].value
    assert df.loc["bv", "unit"] == "N m s/rad"
    d = json.loads(json.dumps(res.to_dict()))
    assert d["parameters"]["J"]["stderr"] == pytest.approx(res.estimates["J"].stderr)
    assert d["stats"]["ndata"] == res.stats.ndata
    assert "<table>" in res._repr_html_() and "NRMSE noisy" in res._repr_html_()
    res.apply(start)
    assert start.value("bv") == res.estimates["bv"].value


def test_lumped_fit_matches_cli_runner(tmp_path):
    from pmdcid.files import run_fit

    paths = []
    for a in ("1.0", "2.0"):
        lg = pmdcid.Log.from_csv(PAPER_DIR / f"step_{a}V.csv")
        p = tmp_path / f"s{a}.csv"
        write_log(p, lg.t, {"v": lg["v"], "omega": lg["omega"]})  # no current: lumped
        paths.append(str(p))
    cli = run_fit("mechanical", paths, str(tmp_path / "m.json"))
    api = pmdcid.fit_mechanical(paths, None)
    assert api.to_dict()["parameters"] == cli.to_dict()["parameters"]
    assert api.estimates["J"].unit == "V s^2/rad"
    model = pmdcid.Model()
    api.apply(model)
    assert model.extra["lumped"] is True
    assert model.parameters["bc"].unit == "V"
    saved = pmdcid.Model.load(tmp_path / "m.json")
    assert saved.value("J") == model.value("J")
    si = model.to_si(km=0.0502, R=2.3724)  # back to SI: J' = J R/km
    assert si.value("J") == pytest.approx(model.value("J") * 0.0502 / 2.3724)


def test_front_door_functions_after_subpackage_imports():
    import pmdcid.identify.runners  # noqa: F401 - would bind pmdcid.identify to the subpackage
    from pmdcid import simulate

    assert callable(pmdcid.identify) and callable(pmdcid.diagnose) and callable(pmdcid.report)
    t = np.arange(0.0, 0.5, 1e-3)
    sim = simulate(pmdcid.Log.from_arrays(t, v=np.where(t > 0.1, 1.0, 0.0)), _truth(),
                   x0=(0.0, 0.5, 0.0))
    assert sim.omega[0] == pytest.approx(0.5, rel=0.01)
    assert list(sim.to_pandas().columns) == ["t", "i", "omega", "theta"]


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_progress_lines_only_on_a_terminal():
    from pmdcid.runtime.progress import resolve, stage_lines

    quiet, tty = io.StringIO(), _Tty()
    stage_lines(quiet)("joint fit")
    stage_lines(tty)("joint fit")
    assert quiet.getvalue() == ""
    assert re.fullmatch(r"\.\.\. joint fit \(\d+ s\)\n", tty.getvalue())
    seen = []
    resolve(seen.append)("x")
    resolve(False)("y")
    assert seen == ["x"]


def test_cli_report_silent_when_stderr_not_a_tty(tmp_path):
    model = _truth()
    model.save(tmp_path / "m.json")
    proc = subprocess.run(
        [sys.executable, "-c", "from pmdcid.cli import main; main()", "report",
         str(PAPER_DIR / "step_1.0V.csv"), "-m", str(tmp_path / "m.json"),
         "-o", str(tmp_path / "rep")],
        capture_output=True, text=True, env={**os.environ, "MPLBACKEND": "Agg"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert "report.html" in proc.stdout


def test_api_doc_examples_run(tmp_path, monkeypatch):
    blocks = re.findall(r"```python\n(.*?)```", (REPO / "docs" / "api.md").read_text(), re.S)
    assert len(blocks) == 2
    (tmp_path / "fixtures").symlink_to(REPO / "fixtures")
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    for b in blocks:
        exec(compile(b, "docs/api.md", "exec"), ns)
    assert (tmp_path / "triangle.png").stat().st_size > 1000
    motor = pmdcid.Model.load(tmp_path / "motor.json")
    truth = _truth()
    for k in ("R", "J", "bv", "bc"):  # the example identifies the fixture's motor
        assert motor.value(k) == pytest.approx(truth.value(k), rel=0.02)
    assert math.isfinite(ns["fit"].estimates["J"].stderr)


def test_diagnose_reports_progress_and_applies():
    seen = []
    res = pmdcid.diagnose(PAPER_DIR / "step_2.0V.csv", _truth(), effects="stribeck",
                          progress=seen.append)
    assert seen and seen[0] == "diagnose round 1: screening 1 effect(s)"
    assert res.summary["added"] == []  # the fixture's motor has no Stribeck friction
    target = pmdcid.Model()
    res.apply(target)
    pd.testing.assert_frame_equal(target.to_pandas(), res.to_pandas())
    assert set(res.to_dict()["parameters"]) >= {"R", "L", "km", "J", "bv", "bc", "dz"}
