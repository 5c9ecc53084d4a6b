"""Round two of bad input (issue 15), the cases a table row cannot express: processes killed or
run side by side, stdout closed, pipes, and the values behind 'exit 0' (a unit converted, a
European export read right, real logs passing the plausibility gate)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from repo_paths import FIXTURES, REAL

from pmdcid.synth import PAPER

FIX = FIXTURES
REAL = REAL
PMDCID = Path(sys.executable).parent / "pmdcid"
EXE = [str(PMDCID)] if PMDCID.exists() else [
    sys.executable, "-c", "import sys; from pmdcid.cli import main; sys.exit(main())"]


def _model(path: Path, **override):
    vals = {**PAPER, **override}
    path.write_text(json.dumps({"parameters": {k: {"value": v} for k, v in vals.items()},
                                "effects": []}))


def _run(args, cwd, **kw):
    env = {k: v for k, v in os.environ.items() if k != "PMDCID_DEBUG"}
    return subprocess.run([*EXE, *args], cwd=cwd, capture_output=True, text=True, env=env,
                          timeout=300, **kw)


def test_model_units_are_converted(tmp_path):
    from pmdcid.model import load_model

    p = tmp_path / "m.json"
    p.write_text(json.dumps({"parameters": {
        "R": {"value": 2370.0, "stderr": 4.0, "unit": "mohm"},
        "L": {"value": 17.8, "unit": "mH"}, "km": {"value": 50.2, "unit": "mN m/A"},
        "J": {"value": 3.1e-3, "unit": "kg m^2"},
        "bc": {"value": 5.0, "unit": "mNm"}}}))
    m = load_model(p)
    assert m.value("R") == pytest.approx(2.37) and m.parameters["R"].stderr == pytest.approx(4e-3)
    assert m.value("L") == pytest.approx(0.0178) and m.value("km") == pytest.approx(0.0502)
    assert m.value("bc") == pytest.approx(5e-3)
    assert m.parameters["R"].unit == "ohm"  # written back in the canonical unit


def test_european_export_reads_the_same_values(tmp_path):
    from pmdcid.io import read_log

    src = FIX / "paper" / "step_1.5V.csv"
    eu = tmp_path / "eu.csv"
    eu.write_text("\n".join(ln if ln.startswith("#") else ln.replace(",", ";").replace(".", ",")
                            for ln in src.read_text().splitlines()) + "\n")
    a, b = read_log(src), read_log(eu)
    for c in a.data:
        np.testing.assert_allclose(b[c], a[c])


def test_expression_mapping_values(tmp_path):
    from pmdcid.io import parse_mapping, read_log

    t = np.arange(100) * 1e-3
    d = (np.arange(100) % 2).astype(float)
    p = tmp_path / "pwm.csv"
    p.write_text("t,pwm,dir,speed [rad/s]\n" + "".join(
        f"{a:.3f},200,{b:g},{3 * a:.6f}\n" for a, b in zip(t, d, strict=True)))
    m = parse_mapping(["v=pwm*(2*dir-1)*12/255", 'omega="speed [rad/s]"*2'])
    log = read_log(p, m)
    np.testing.assert_allclose(log["v"], 200 * (2 * d - 1) * 12 / 255)
    np.testing.assert_allclose(log["omega"], 6 * t, atol=1e-6)


def test_piped_log_is_read_once(tmp_path):
    """A FIFO (what ``<(zcat log.gz)`` gives) is read once and not sized."""
    from pmdcid.io import read_log

    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)
    data = (FIX / "paper" / "step_1.5V.csv").read_bytes()

    def writer():
        with open(fifo, "wb") as fh:
            fh.write(data)

    th = threading.Thread(target=writer)
    th.start()
    log = read_log(fifo)
    th.join(timeout=30)
    ref = read_log(FIX / "paper" / "step_1.5V.csv")
    np.testing.assert_allclose(log["omega"], ref["omega"])


def test_symlinked_model_stays_a_link(tmp_path):
    (tmp_path / "real").mkdir()
    _model(tmp_path / "real" / "m.json", R=1.0)
    (tmp_path / "model.json").symlink_to("real/m.json")
    (tmp_path / "b.csv").write_bytes((FIX / "paper" / "blocked_1.5V.csv").read_bytes())
    res = _run(["fit-electrical", "b.csv", "-m", "model.json"], tmp_path)
    assert res.returncode == 0, res.stderr
    assert (tmp_path / "model.json").is_symlink()
    r = json.loads((tmp_path / "real" / "m.json").read_text())["parameters"]["R"]["value"]
    assert r == pytest.approx(PAPER["R"], rel=0.05)


def test_two_stages_at_once_both_land(tmp_path):
    """fit-electrical and fit-mechanical on one model at the same time: R, L and J all written."""
    _model(tmp_path / "model.json")
    data = json.loads((tmp_path / "model.json").read_text())
    for k in ("J", "b", "bv", "bc"):
        data["parameters"].pop(k, None)
    (tmp_path / "model.json").write_text(json.dumps(data))
    (tmp_path / "b.csv").write_bytes((FIX / "paper" / "blocked_1.5V.csv").read_bytes())
    (tmp_path / "s.csv").write_bytes((FIX / "paper" / "step_1.5V.csv").read_bytes())
    env = {k: v for k, v in os.environ.items() if k != "PMDCID_DEBUG"}
    procs = [subprocess.Popen([*EXE, *args], cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                              stderr=subprocess.PIPE, text=True)
             for args in (["fit-electrical", "b.csv", "-m", "model.json"],
                          ["fit-mechanical", "s.csv", "-m", "model.json"])]
    for p in procs:
        _, err = p.communicate(timeout=300)
        assert p.returncode == 0, err
    params = json.loads((tmp_path / "model.json").read_text())["parameters"]
    assert params["L"]["stage"] == "fit-electrical"
    assert params["J"]["stage"] == "fit-mechanical"


def test_stdout_full_restores_the_model(tmp_path):
    """Exit 1 when the final message cannot be written (stdout is /dev/full): the model file is
    as it was, and no new file is left."""
    if not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    _model(tmp_path / "model.json", R=1.0)
    before = (tmp_path / "model.json").read_bytes()
    (tmp_path / "b.csv").write_bytes((FIX / "paper" / "blocked_1.5V.csv").read_bytes())
    with open("/dev/full", "w") as full:
        env = {k: v for k, v in os.environ.items() if k != "PMDCID_DEBUG"}
        res = subprocess.run([*EXE, "fit-electrical", "b.csv", "-m", "model.json"],
                             cwd=tmp_path, stdout=full, stderr=subprocess.PIPE, text=True,
                             env=env, timeout=300)
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr
    assert (tmp_path / "model.json").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.csv", "model.json"]


def test_sigterm_leaves_no_temporary_file(tmp_path):
    """SIGTERM while simulate writes a large output: no hidden .tmp file, no partial output."""
    n = 1_000_000
    t = np.arange(n) * 1e-4
    (tmp_path / "in.csv").write_text("t,v\n" + "\n".join(f"{x:.4f},1" for x in t) + "\n")
    _model(tmp_path / "model.json")
    env = {k: v for k, v in os.environ.items() if k != "PMDCID_DEBUG"}
    proc = subprocess.Popen([*EXE, "simulate", "in.csv", "-m", "model.json", "-o", "out.csv"],
                            cwd=tmp_path, env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 240
    while time.monotonic() < deadline and proc.poll() is None:
        if any(p.name.endswith(".tmp") for p in tmp_path.iterdir()):
            break
        time.sleep(0.02)
    if proc.poll() is not None:
        pytest.skip("simulate finished before it could be interrupted")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0
    assert "Traceback" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in.csv", "model.json"]


def test_real_logs_pass_the_gate():
    """No real measured log trips the plausibility gate (nor any bundled fixture)."""
    from pmdcid.identify.plausibility import log_issues, speed_issue
    from pmdcid.io import parse_mapping, read_log

    logs = sorted(REAL.glob("*/*.csv")) if REAL.exists() else []
    paths = logs + sorted((FIX / "paper").glob("*.csv")) + sorted((FIX / "hidden").glob("*.csv"))
    for p in paths:
        log = read_log(p, defer=True)
        assert log_issues(log) == [], p
        if "real" not in str(p):
            assert speed_issue(log, PAPER["km"], PAPER["R"]) is None, p
    emps = sorted((FIX / "emps").glob("*.csv"))
    m = parse_mapping(["t=t_s", "theta=qm_meas_m", "tau=force_N"])
    for p in emps:
        assert log_issues(read_log(p, m, defer=True)) == [], p
    if not logs:
        pytest.skip("real logs absent (../shared/data/real): only the fixtures were checked")


def test_error_lines_stay_short():
    from pmdcid.errors import MAX_MESSAGE, LogError

    e = LogError("x" * 200_000 + " do this", "a.csv")
    assert len(str(e)) <= MAX_MESSAGE and str(e).endswith("do this")
