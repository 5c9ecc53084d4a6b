"""Parquet files as pandas/pyarrow loggers write them, beyond a table of float64 columns: each
written with pyarrow, then read."""

from __future__ import annotations

import numpy as np
import pytest
from read_util import STEP_N, run_cli, step_motor

N = STEP_N
EPOCH_NS = 1_700_000_000_000_000_000




def test_int64_nanoseconds_beyond_2_53_are_read(tmp_path):
    """An int64 time column in ns since 1970 (beyond 2**53): before, every command stopped with
    'internal error ArrowInvalid: Integer value ... not in range'; now it is read (rounded to
    float64, as numpy would) and the mapping converts it."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    from pmdcid.io import parse_mapping, read_log

    t, v, w = step_motor(2)
    ns = EPOCH_NS + np.round(t * 1e9).astype(np.int64)
    p = tmp_path / "log.parquet"
    pq.write_table(pa.table({"t_ns": ns, "v": v, "omega": w}), p)
    code, out, err = run_cli(["channels", p])
    assert code == 0 and "t_ns" in out, err
    log = read_log(p, parse_mapping(["t=t_ns*1e-9"]))
    assert log.n == N and log.dt == pytest.approx(1e-3, rel=1e-3)
    np.testing.assert_array_equal(log["v"], v)


def test_time_in_nanoseconds_is_named_so(tmp_path):
    """The same column left unmapped: before, 't looks like microseconds (... us would make it
    0.999936 s): map it with -c t=COLUMN*us', a fix that gives a 1 s sample period; now it names
    nanoseconds and the factor that gives 1 ms."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    t, v, w = step_motor(3)
    p = tmp_path / "log.parquet"
    pq.write_table(pa.table({"t": EPOCH_NS + np.round(t * 1e9).astype(np.int64), "v": v,
                             "omega": w}), p)
    code, _, err = run_cli(["fit-mechanical", p, "-m", tmp_path / "m.json", "--km", "0.05"])
    assert code == 1 and len(err) == 1, err
    assert "t looks like nanoseconds" in err[0] and "-c t=COLUMN*1e-9" in err[0], err


@pytest.mark.parametrize("kind", ["timestamp", "duration"])
def test_a_timestamp_column_is_the_time(tmp_path, kind):
    """A table whose time is a pyarrow timestamp (what ``DataFrame.to_parquet`` writes for a
    date-time index or column) or a duration, under a name of its own: before, 'has no time
    column t' (its CSV twin, ISO date-times, was read); now it is the time, with one line."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    from pmdcid.io import read_log

    t, v, w = step_motor(4)
    ns = np.round(t * 1e9).astype(np.int64) + (EPOCH_NS if kind == "timestamp" else 0)
    col = pa.array(ns, type=pa.timestamp("ns") if kind == "timestamp" else pa.duration("ns"))
    p = tmp_path / "log.parquet"
    pq.write_table(pa.table({"time": col, "v": v, "omega": w}), p)
    with pytest.warns(UserWarning, match="column 'time' is stored as times: read as t"):
        log = read_log(p)
    # seconds from 1970 in float64 are quantised to 0.24 us: the period to 1e-4
    assert log.n == N and log.dt == pytest.approx(1e-3, rel=1e-4)
    np.testing.assert_array_equal(log["v"], v)


def test_two_timestamp_columns_are_not_guessed(tmp_path):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    from pmdcid.errors import LogError
    from pmdcid.io import read_log

    t, v, w = step_motor(5)
    ts = pa.array(EPOCH_NS + np.round(t * 1e9).astype(np.int64), type=pa.timestamp("ns"))
    p = tmp_path / "log.parquet"
    pq.write_table(pa.table({"sent": ts, "received": ts, "v": v, "omega": w}), p)
    with pytest.raises(LogError, match=r"several columns of times \(sent, received\)"):
        read_log(p)
