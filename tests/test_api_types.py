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
    ("model", lambda: pmdcid.export({"R": 1.0}, "c", "x.c")),
    ("model", lambda: pmdcid.export(5, "python-control", "x.py")),
    ("to", lambda: pmdcid.export(TRUTH, 5, "x.c")),
    ("output", lambda: pmdcid.export(TRUTH, "c", 5)),
    ("model", lambda: pmdcid.plan({"R": 1.0})),
    ("vmax", lambda: pmdcid.plan(vmax="12")),
    ("path", lambda: pmdcid.api.channels(5)),
    ("encoder", lambda: pmdcid.api.simulate_to(STEP, TRUTH, "o.csv", encoder=1.5)),
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


def _rpm_log(tmp_path) -> str:
    """The paper's step log with its speed as ``speed_rpm`` (rpm) instead of omega."""
    import pandas as pd

    df = pd.read_csv(STEP, comment="#")
    df["speed_rpm"] = df.pop("omega") * 60 / (2 * math.pi)
    path = tmp_path / "rpm.csv"
    df.to_csv(path, index=False)
    return str(path)


@pytest.mark.parametrize("form", ["str", "list", "tuple", "dict", "file", "path", "columnmap"])
def test_mapping_in_every_form_the_cli_takes(tmp_path, form):
    """``mapping=`` as -c takes it (one string, several), a dict, a --map file (str or Path) or a
    ColumnMap: the same omega, in rad/s, as the CLI's parse_mapping gives."""
    from pathlib import Path

    from pmdcid.api import _logs
    from pmdcid.io import parse_mapping

    csv = _rpm_log(tmp_path)
    item = "omega=speed_rpm*rpm"
    (tmp_path / "map.txt").write_text(item + "\n")
    given = {"str": item, "list": [item], "tuple": (item,), "dict": {"omega": "speed_rpm*rpm"},
             "file": str(tmp_path / "map.txt"), "path": Path(tmp_path / "map.txt"),
             "columnmap": parse_mapping([item])}[form]
    want = _logs(csv, mapping=parse_mapping([item]))[0]["omega"]
    got = _logs(csv, mapping=given)[0]["omega"]
    assert np.array_equal(got, want)
    assert np.allclose(got, _logs(STEP)[0]["omega"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("bad", [5, ["omega=speed_rpm*rpm", 3], {"omega": None}, b"omega=x",
                                 {"omega": ["speed_rpm"]}])
def test_mapping_of_another_type_is_one_line(bad):
    """Anything else: one PmdcidError line naming the accepted forms, before any work."""
    from pmdcid.errors import PmdcidError

    with pytest.raises(PmdcidError, match="mapping takes") as exc:
        pmdcid.identify(STEP, mapping=bad, diagnose=False)
    assert "\n" not in str(exc.value)


#: values of the right type the command line refuses (as usage errors): the front door refuses
#: them too, as one line of the library's error family (which is a ValueError too)
BAD_VALUES = [
    ("km", lambda: pmdcid.identify(STEP, None, km=-1)),
    ("km", lambda: pmdcid.fit_mechanical(STEP, TRUTH, km=0.0)),
    ("x0", lambda: pmdcid.simulate(STEP, TRUTH, x0={"speed": 1.0})),
    ("x0", lambda: pmdcid.simulate(STEP, TRUTH, x0=[1.0, 2.0])),
    ("x0", lambda: pmdcid.simulate(STEP, TRUTH, x0=(0.0, math.inf, 0.0))),
    ("vmax", lambda: pmdcid.plan(vmax=-12)),
    ("taumax", lambda: pmdcid.plan(taumax=0.0)),
    ("speed_max", lambda: pmdcid.plan(TRUTH, speed_max=-1.0)),
    ("rate", lambda: pmdcid.plan(vmax=12, rate=-5)),
    ("budget", lambda: pmdcid.plan(vmax=12, budget=math.nan)),
    ("budget", lambda: pmdcid.plan(vmax=12, rate=1e6)),
    ("noise_omega", lambda: pmdcid.api.check_plan(STEP, TRUTH, noise_omega=-0.1)),
    ("noise_i", lambda: pmdcid.api.simulate_to(STEP, TRUTH, "o.csv", noise_i=-1.0)),
    ("encoder", lambda: pmdcid.api.simulate_to(STEP, TRUTH, "o.csv", encoder=-1)),
]


@pytest.mark.parametrize("arg, call", BAD_VALUES,
                         ids=[f"{a}-{k}" for k, (a, _) in enumerate(BAD_VALUES)])
def test_values_the_cli_refuses_are_one_pmdcid_error(arg, call, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(pmdcid.PmdcidError) as info:
        call()
    assert isinstance(info.value, ValueError)
    assert str(info.value).startswith(arg) and "\n" not in str(info.value), str(info.value)
    assert not list(tmp_path.iterdir())  # refused before any work


def test_names_as_the_command_line_gives_them():
    """``free="J,bv"`` is the list ``["J", "bv"]``, as ``--free J,bv`` (and diagnose's
    ``effects="stribeck"`` one name)."""
    res = pmdcid.fit_nonlinear(STEP, TRUTH, free="J, bv")
    assert sorted(res.to_dict()["parameters"]) == ["J", "bv"]
