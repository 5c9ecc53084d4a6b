import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from pmdcid.synth import PAPER

if os.environ.get("PYTEST_XDIST_WORKER"):
    # pytest -n already runs a worker per CPU: the fits' Jacobian threads would oversubscribe
    # (fit/fdjac.py; tests/fit/test_fdjac.py runs the threads itself). Children inherit it.
    os.environ.setdefault("PMDCID_THREADS", "1")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


@pytest.fixture
def paper_step(tmp_path, monkeypatch):
    """A folder (the working directory) holding the paper's true model ``m.json`` and one of
    its step logs ``step.csv``: what a command-line test runs on."""
    fix = Path(__file__).resolve().parents[1] / "fixtures" / "paper"
    monkeypatch.chdir(tmp_path)
    shutil.copy(fix / "truth.json", tmp_path / "m.json")
    shutil.copy(fix / "step_1.5V.csv", tmp_path / "step.csv")
    return tmp_path


@pytest.fixture
def paper_values():
    from pmdcid.simulate import neutral_values

    return {**neutral_values(), **PAPER}


#: whole-pipeline modules (diagnose round trips, real rigs, a browser, compilers, Monte Carlo,
#: subprocess races): `make test-fast` (-m "not slow") leaves them to `make test`
SLOW_MODULES = {
    "test_api", "test_demo", "test_diagnose", "test_diagnose_real", "test_drive_effects",
    "test_emps", "test_export_native", "test_friction_curve", "test_lugre", "test_outputs_safety",
    "test_plan", "test_read_log_hypothesis", "test_real_rigs", "test_real_rigs_synthetic",
    "test_real_steps", "test_report", "test_report_browser", "test_report_parallel",
}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if item.module is not None and item.module.__name__.rsplit(".", 1)[-1] in SLOW_MODULES:
            item.add_marker(pytest.mark.slow)
