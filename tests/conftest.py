# ruff: noqa: E402  (the BLAS kernels are pinned before numpy loads)
import os
import shutil
from pathlib import Path

from pmdcid.runtime.blas import pin_blas_kernels

pin_blas_kernels()  # the command line's BLAS kernels, before numpy loads (runtime/blas.py)

import numpy as np
import pytest
from repo_paths import FIXTURES

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
    fix = FIXTURES / "paper"
    monkeypatch.chdir(tmp_path)
    shutil.copy(fix / "truth.json", tmp_path / "m.json")
    shutil.copy(fix / "step_1.5V.csv", tmp_path / "step.csv")
    return tmp_path


@pytest.fixture
def paper_values():
    from pmdcid.simulate import neutral_values

    return {**neutral_values(), **PAPER}


#: whole-pipeline tests (diagnose round trips, real rigs, a browser, compilers and Octave, a
#: Dask cluster, Monte Carlo, subprocess races) live in tests/system/: slow by folder, `make
#: test-fast` (-m "not slow") leaves them to `make test`
SYSTEM = Path(__file__).resolve().parent / "system"


def pytest_collection_modifyitems(config, items):
    for item in items:
        if SYSTEM in Path(str(item.fspath)).resolve().parents:
            item.add_marker(pytest.mark.slow)
