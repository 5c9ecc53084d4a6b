"""report with a lumped (per-volt) model on logs that carry a current. identify writes such a
model for a lab rig with blocked-rotor steps and free steps with current but no --km (R from the
blocked rotor, no km: the mechanics per volt). Before, every log with a current column stopped
`report` (and `identify -o`, after all its fits, writing no model) with 'the model's simulated i
is not finite on this log (check the model's parameters)': a lumped model simulates no current.
Now the current is not compared with a lumped model, and blocked-rotor logs (current only) are
left out of its report with a warning; identify's report holds a rotor it sorted blocked by its
content."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner

from pmdcid.cli import main
from pmdcid.io import read_log

LUMPED = {"J": (1.28e-3, "V s^2/rad"), "bv": (0.0307, "V s/rad"), "b": (0.0332, "V s/rad"),
          "bc": (0.26, "V"), "R": (3.2, "ohm"), "L": (4e-3, "H")}


def _model(p):
    p.write_text(json.dumps({"format": 1, "lumped": True, "effects": [], "parameters": {
        k: {"value": v, "stderr": None, "unit": u, "stage": "fit-nonlinear"}
        for k, (v, u) in LUMPED.items()}}))


def _free_log(p, seed=1):
    rng = np.random.default_rng(seed)
    t = np.arange(2000) * 5e-4
    v = np.where(t > 0.1, 6.0, 0.0)
    w = np.where(t > 0.1, 180 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.04)), 0.0)
    i = np.where(t > 0.1, 0.3 + 1.5 * np.exp(-np.clip(t - 0.1, 0, None) / 0.04), 0.0)
    np.savetxt(p, np.c_[t, v, i + rng.normal(0, 0.004, t.size), w + rng.normal(0, 0.3, t.size)],
               delimiter=",", header="t,v,i,omega", comments="")


def _blocked_log(p, seed=2):
    rng = np.random.default_rng(seed)
    t = np.arange(200) * 5e-4
    v = np.where(t > 0.02, 4.0, 0.0)
    i = np.where(t > 0.02, 1.25 * (1 - np.exp(-np.clip(t - 0.02, 0, None) / 1.25e-3)), 0.0)
    with open(p, "w") as fh:
        fh.write("# kind: blocked-rotor\nt,v,i\n")
        np.savetxt(fh, np.c_[t, v, i + rng.normal(0, 0.004, t.size)], delimiter=",")


def test_lumped_model_report_on_logs_with_current(tmp_path):
    _model(tmp_path / "m.json")
    _free_log(tmp_path / "free.csv")
    _blocked_log(tmp_path / "blocked.csv")
    r = CliRunner().invoke(main, ["report", str(tmp_path / "free.csv"),
                                  str(tmp_path / "blocked.csv"),
                                  "-m", str(tmp_path / "m.json"), "-o", str(tmp_path / "rep")])
    assert r.exit_code == 0, r.output            # before: exit 1, 'simulated i is not finite'
    assert "blocked-rotor log(s) left out of the report" in r.output
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert [lg["name"] for lg in metrics["logs"]] == ["free"]
    assert set(metrics["logs"][0]["signals"]) == {"omega", "theta"}


def test_lumped_model_report_on_blocked_logs_only_is_one_line(tmp_path):
    _model(tmp_path / "m.json")
    _blocked_log(tmp_path / "blocked.csv")
    r = CliRunner().invoke(main, ["report", str(tmp_path / "blocked.csv"), "-m",
                                  str(tmp_path / "m.json"), "-o", str(tmp_path / "rep")])
    assert r.exit_code == 1
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: ") and "lumped" in lines[0], r.output


def test_identify_report_holds_a_rotor_sorted_blocked_by_content(tmp_path):
    """A blocked-rotor log without '# kind:' whose speed column reads ~0: identify sorts it
    blocked by its content; its report showed it simulated turning freely."""
    from pmdcid.files import _as_sorted

    rng = np.random.default_rng(3)
    t = np.arange(200) * 5e-4
    v = np.where(t > 0.02, 4.0, 0.0)
    np.savetxt(tmp_path / "b.csv", np.c_[t, v, v / 3.2, rng.normal(0, 0.05, t.size)],
               delimiter=",", header="t,v,i,omega", comments="")
    log = read_log(tmp_path / "b.csv")
    assert not log.blocked
    shown = _as_sorted(log, "blocked")
    assert shown.blocked and not log.blocked    # the log read stays as it was
    assert _as_sorted(log, "step") is log


def test_fit_electricals_model_alone_reports_its_blocked_rotor(tmp_path):
    """A model of fit-electrical alone (R, L: no J, no km) on the blocked-rotor log it was fitted
    on: the held rotor's current needs neither, so the report shows it (before: 'model lacks
    km, J needed to simulate'); beside a free-running log the same model says what it lacks."""
    _blocked_log(tmp_path / "blocked.csv")
    _free_log(tmp_path / "free.csv")
    m = tmp_path / "m.json"
    out = CliRunner().invoke(main, ["fit-electrical", str(tmp_path / "blocked.csv"), "-m", str(m)])
    assert out.exit_code == 0, out.output
    out = CliRunner().invoke(main, ["report", str(tmp_path / "blocked.csv"), "-m", str(m),
                                    "-o", str(tmp_path / "rep")])
    assert out.exit_code == 0, out.output
    metrics = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    # L/R is 2.5 samples here: L is written as an interval, its middle simulated
    assert metrics["logs"][0]["signals"]["i"]["nrmse"] < 0.15, metrics["logs"][0]
    out = CliRunner().invoke(main, ["report", str(tmp_path / "blocked.csv"),
                                    str(tmp_path / "free.csv"), "-m", str(m), "-o",
                                    str(tmp_path / "rep2")])
    assert out.exit_code == 1 and "model lacks km, J" in out.output
