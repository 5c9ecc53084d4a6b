"""pmdcid/io/build.py: filling short NaN gaps, and columns that hold no numbers at all."""

import numpy as np
import pytest

from pmdcid.errors import LogError
from pmdcid.io import read_log, write_log


def _write(p, t, **cols):
    write_log(p, t, cols)
    return p


def test_a_missing_input_sample_holds_the_one_before_measurements_interpolate(tmp_path):
    t = np.arange(400) * 1e-3
    v = np.where(t >= 0.2, 2.0, 0.0)
    v[200] = np.nan  # the first sample of a step: the drive still held 0 V there
    v[0] = np.nan  # the first sample: nothing before it, the next one is taken
    omega = np.sin(t)
    omega[200] = np.nan
    p = _write(tmp_path / "a.csv", t, v=v, omega=omega)
    with pytest.warns(UserWarning) as got:
        log = read_log(p)
    said = [str(w.message) for w in got]
    assert any("column 'v': filled 2 NaN value(s) by holding the sample before (the input is "
               "zero-order held)" in m for m in said), said
    assert any("column 'omega': filled 1 NaN value(s) by linear interpolation" in m
               for m in said), said
    assert log["v"][200] == 0.0 and log["v"][201] == 2.0 and log["v"][0] == 0.0
    assert log["omega"][200] == pytest.approx(np.sin(0.2), abs=1e-6)


def test_a_missing_torque_sample_is_held_too(tmp_path):
    t = np.arange(400) * 1e-3
    tau = np.where(t >= 0.1, 0.01, 0.0)
    tau[300] = np.nan
    p = _write(tmp_path / "a.csv", t, tau=tau, omega=t)
    with pytest.warns(UserWarning, match="column 'tau': filled 1 NaN value.* holding"):
        log = read_log(p)
    assert log["tau"][300] == 0.01


def test_an_empty_column_is_as_if_absent(tmp_path):
    t = np.arange(400) * 1e-3
    p = tmp_path / "a.csv"
    p.write_text("t,v,i,omega\n" + "".join(f"{a:.3f},1,,{a:.3f}\n" for a in t))
    with pytest.warns(UserWarning, match=r"column 'i' is empty \(no number in any row\): ignored"):
        log = read_log(p)
    assert not log.has("i") and log.has("omega") and log.has("theta")  # theta from omega
    with pytest.raises(LogError, match=r"needs column\(s\) i for R; column 'i' is empty; "
                                       r"it has v, omega, theta"):
        log.require("i", purpose="R")
