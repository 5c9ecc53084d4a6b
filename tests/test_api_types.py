"""Round three, family 6 (issue 29): the Python API's argument types. A wrong type raises a
TypeError naming the argument (a bad value a ValueError or PmdcidError), before any work --
never an AttributeError or TypeError from deep inside."""

from __future__ import annotations

import math

import numpy as np
import pytest
from repo_paths import FIXTURES

import pmdcid
from pmdcid import Log, Model

FIX = FIXTURES
STEP = str(FIX / "paper" / "step_1.5V.csv")
TRUTH = str(FIX / "paper" / "truth.json")
T = np.arange(100) * 1e-3

CASES = [
    ("df", lambda: Log.from_dataframe({"t": [0.0, 1e-3, 2e-3], "v": [1.0, 1.0, 1.0]})),
    ("df", lambda: Log.from_dataframe(None)),
    ("t", lambda: Log.from_arrays(1.0, v=np.ones(100), omega=np.ones(100))),
    ("t", lambda: Log.from_arrays(np.ones((100, 2)), v=np.ones(100), omega=np.ones(100))),
    ("omega", lambda: Log.from_arrays(T, v=np.ones(100), omega="fast")),
    ("model", lambda: pmdcid.simulate(STEP, {"R": 2.37})),
    ("model", lambda: pmdcid.simulate(STEP, 5)),
    ("log_or_input", lambda: pmdcid.simulate({"t": T, "v": T}, TRUTH)),
    ("x0", lambda: pmdcid.simulate(STEP, TRUTH, x0="rest")),
    ("x0", lambda: pmdcid.simulate(STEP, TRUTH, x0=(0.0, math.nan, 0.0))),
    ("x0", lambda: pmdcid.simulate(STEP, TRUTH, x0=(0.0, 1.0))),
    ("logs", lambda: pmdcid.fit_electrical(None)),
    ("logs[1]", lambda: pmdcid.fit_electrical([STEP, 3])),
    ("model", lambda: pmdcid.fit_mechanical(STEP, {"R": 2.37})),
    ("km", lambda: pmdcid.fit_mechanical(STEP, TRUTH, km="0.05")),
    ("km", lambda: pmdcid.identify(STEP, None, km=-1.0)),
    ("free", lambda: pmdcid.fit_nonlinear(STEP, TRUTH, free=5)),
    ("effects", lambda: pmdcid.diagnose(STEP, TRUTH, effects=[1, 2])),
    ("out_dir", lambda: pmdcid.report(STEP, TRUTH, 5)),
    ("before", lambda: pmdcid.report(STEP, TRUTH, "rep", before={"R": 1.0})),
    ("path", lambda: Model.load(5)),
    ("path", lambda: Model().save(None)),
]


@pytest.mark.parametrize("arg, call", CASES, ids=[f"{a}-{k}" for k, (a, _) in enumerate(CASES)])
def test_wrong_argument_types_name_the_argument(arg, call, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises((TypeError, ValueError)) as info:
        call()
    assert str(info.value).startswith(arg), str(info.value)
    assert not list(tmp_path.iterdir())  # refused before any work
