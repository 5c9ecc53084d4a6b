"""pmdcid/io/build.py: filling short NaN gaps, columns that hold no numbers at all, and a
DataFrame's time in its index or in a date-time column."""

import warnings

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


def _frame_parts(rng, n=600):
    t = np.arange(n) * 1e-3
    v = np.where(t > 0.1, 2.0, 0.0)
    return t, v, np.cumsum(v) * 0.01 + rng.normal(0, 1e-3, n)


@pytest.mark.parametrize("index", ["datetime", "timedelta", "named t", "named time [ms]"])
def test_a_dataframe_whose_time_is_its_index(rng, index):
    """pandas keeps a time series' time in its index: before, every such frame was refused
    ('has no time column t'); now the index is read as a column of that name, so a date-time
    or duration index is the time, and a numeric one is read by its name as any column."""
    import pandas as pd

    from pmdcid.io.logs import Log

    t, v, w = _frame_parts(rng)
    idx = {"datetime": pd.date_range("2026-01-01 12:00", periods=len(t), freq="1ms"),
           "timedelta": pd.to_timedelta(t, unit="s"), "named t": pd.Index(t, name="t"),
           "named time [ms]": pd.Index(t * 1e3, name="time [ms]")}[index]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        log = Log.from_dataframe(pd.DataFrame({"v": v, "omega": w}, index=idx))
    assert log.n == len(t) and log.dt == pytest.approx(1e-3, rel=1e-9)
    np.testing.assert_array_equal(log["v"], v)


def test_a_datetime64_column_is_the_time_and_a_default_index_is_not(rng):
    import pandas as pd

    from pmdcid.io.logs import Log

    t, v, w = _frame_parts(rng)
    stamps = pd.date_range("2026-01-01 23:59:59.5", periods=len(t), freq="1ms", tz="UTC")
    with pytest.warns(UserWarning, match="column 'stamp' holds date-times"):
        log = Log.from_dataframe(pd.DataFrame({"stamp": stamps, "v": v, "omega": w}))
    np.testing.assert_allclose(log.t, t, atol=1e-9)
    with pytest.raises(LogError, match="has no time column 't'"):
        Log.from_dataframe(pd.DataFrame({"v": v, "omega": w}))  # a RangeIndex is no time


def test_a_mapping_names_the_index(rng):
    import pandas as pd

    from pmdcid.io.logs import Log

    t, v, w = _frame_parts(rng)
    df = pd.DataFrame({"v": v, "omega": w}, index=pd.Index(t * 1e3, name="stamp"))
    log = Log.from_dataframe(df, columns={"t": "stamp*ms"})
    np.testing.assert_allclose(log.t, t, atol=1e-12)
