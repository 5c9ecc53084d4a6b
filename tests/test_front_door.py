"""The notebook user's front door (issue #26): ``pmdcid.identify``, ``.diagnose``, ``.simulate``,
``.report``, ``.plan``, ``.export`` are plain functions with their own signatures and docstrings
whatever was imported before; every import form still reaches the subpackages; logs and
simulations have short reprs and ``.plot()``."""

from __future__ import annotations

import inspect
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from repo_paths import REPO

import pmdcid
from pmdcid import api

REPO = REPO
PAPER_DIR = REPO / "fixtures" / "paper"
NAMES = ("identify", "diagnose", "simulate", "report", "plan", "export")


def _truth() -> pmdcid.Model:
    m = pmdcid.Model()
    for k, v in json.loads((PAPER_DIR / "truth.json").read_text())["parameters"].items():
        m.set(k, v)
    return m


def test_front_door_names_are_functions_after_the_subpackages_are_imported():
    """In a fresh interpreter: the subpackages imported first (which binds them on the
    package), then each name is the api function, with its own signature and docstring."""
    code = (
        "import inspect, sys\n"
        "import pmdcid.identify.runners, pmdcid.diagnose.loop, pmdcid.simulate.kernel\n"
        "import pmdcid.report.figures, pmdcid.plan.design, pmdcid.export.c_source\n"
        "import pmdcid, pmdcid.api as api\n"
        f"for n in {NAMES!r}:\n"
        "    f = getattr(pmdcid, n)\n"
        "    assert inspect.isfunction(f) and f is getattr(api, n), (n, f)\n"
        "    assert f.__doc__ == getattr(api, n).__doc__, n\n"
        "    print(n, inspect.signature(f))\n")
    here = Path(pmdcid.__file__).resolve().parents[1]  # the checkout under test
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=here)
    assert out.returncode == 0, out.stderr
    sigs = dict(line.split(" ", 1) for line in out.stdout.splitlines())
    assert sigs["identify"].startswith("(logs, model=None, *, km")
    assert sigs["simulate"].startswith("(log_or_input, model, *, x0=None)")
    assert "vmax" in sigs["plan"] and "output" in sigs["export"]


def test_signature_and_help_are_the_functions_own():
    sig = inspect.signature(pmdcid.identify)
    assert list(sig.parameters)[:2] == ["logs", "model"]
    assert sig.parameters["km"].kind is inspect.Parameter.KEYWORD_ONLY
    assert pmdcid.identify.__doc__.startswith("A whole rig")
    assert "Identification stages" not in pmdcid.identify.__doc__


def test_every_import_form_still_reaches_the_subpackages(monkeypatch):
    import pmdcid.export as ex
    import pmdcid.identify.steps as steps
    import pmdcid.report.parallel as par
    from pmdcid import simulate
    from pmdcid.simulate import SimResult

    assert steps.__name__ == "pmdcid.identify.steps" and par.__name__ == "pmdcid.report.parallel"
    assert simulate is api.simulate and ex is api.export
    assert pmdcid.simulate is api.simulate  # importing submodules did not rebind it
    # the function's attributes are its subpackage's namespace
    assert pmdcid.simulate.SimResult is SimResult and pmdcid.identify.steps is steps
    assert ex.FORMATS == sys.modules["pmdcid.export"].FORMATS
    monkeypatch.setattr("pmdcid.identify.steps.held_steps", lambda *a: 7)
    assert steps.held_steps() == 7
    monkeypatch.setattr(ex, "MARKER", "patched")
    assert sys.modules["pmdcid.export"].MARKER == "patched"


def test_log_and_simulation_reprs_are_short():
    t = np.arange(0.0, 20.0, 1e-3)
    log = pmdcid.Log.from_arrays(t, v=np.where(t > 1.0, 2.0, 0.0), name="cmd.csv")
    sim = pmdcid.simulate(log, _truth())
    for text in (repr(log), repr(sim), str(sim)):
        assert len(text) < 200 and "array" not in text and "..." not in text, text
    assert "20000 samples" in repr(log) and "1000 Hz" in repr(log)
    assert "omega" in repr(sim) and "rad/s" in repr(sim)


def test_plot_returns_a_figure_input_on_top_measured_beside_model():
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    log = pmdcid.Log.from_csv(PAPER_DIR / "step_1.0V.csv")
    fig = log.plot()
    assert isinstance(fig, Figure)
    assert fig.axes[0].get_ylabel() == "voltage [V]"
    assert [ax.get_ylabel() for ax in fig.axes][1:] == ["current [A]", "speed [rad/s]",
                                                        "angle [rad]"]
    sim = pmdcid.simulate(log, _truth())
    fig2 = sim.plot(log)
    speed = fig2.axes[2]
    assert [ln.get_label() for ln in speed.lines] == ["measured", "model"]
    assert len(sim.plot().axes) == 3
    import matplotlib.pyplot as plt

    plt.close("all")


def test_plan_and_export_in_the_api(tmp_path):
    plan = pmdcid.plan(vmax=12.0, out_dir=tmp_path / "plan")
    written = json.loads((tmp_path / "plan" / "plan.json").read_text())
    assert len(plan.profiles) == len(written["profiles"]) >= 2
    assert len(repr(plan)) < 200 and "array" not in repr(plan) and "profiles" in repr(plan)
    with pytest.raises(pmdcid.PmdcidError, match="vmax"):
        pmdcid.plan()
    out = pmdcid.export(_truth(), "python-control", tmp_path / "motor.py")
    assert out == [str(tmp_path / "motor.py")]
    assert "make_system" in (tmp_path / "motor.py").read_text()
