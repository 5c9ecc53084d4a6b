"""Units a log file stores with its signals, written by each format's own library: a speed
channel in rpm read bare (``-c omega=speed``) was taken as rad/s, J 9.5 x too small, with no
word. Now a stored unit of the column's quantity is applied (one warning says so), one of
another quantity is refused, an unknown one is read as it stands with a warning, and a mapping
with a scale is the whole conversion."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from read_util import STEP_N, step_motor

from pmdcid.errors import LogError
from pmdcid.io import parse_mapping, read_log

N = STEP_N
RPM = 60 / (2 * np.pi)



def _read(p, mapping):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(p, parse_mapping(mapping))
    return log, [str(w.message) for w in caught]


def _mdf(p, t, v, speed, unit):
    asammdf = pytest.importorskip("asammdf")
    m = asammdf.MDF(version="4.10")
    m.append([asammdf.Signal(v, t, name="u_arm", unit="V"),
              asammdf.Signal(speed, t, name="n_mot", unit=unit)], acq_name="motor")
    m.save(p, overwrite=True)
    m.close()
    return ["v=u_arm", "omega=n_mot"]


def _tdms(p, t, v, speed, unit):
    nptdms = pytest.importorskip("nptdms")
    wf = {"wf_increment": 1e-3, "wf_start_offset": 0.0}
    with nptdms.TdmsWriter(p) as w:
        w.write_segment([nptdms.ChannelObject("drive", "voltage", v, properties=wf),
                         nptdms.ChannelObject("encoder", "speed", speed,
                                              properties={**wf, "unit_string": unit})])
    return ["v=drive/voltage", "omega=encoder/speed"]


def _parquet(p, t, v, speed, unit):
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    schema = pa.schema([pa.field("t", pa.float64()), pa.field("volts", pa.float64()),
                        pa.field("speed", pa.float64(), metadata={"unit": unit})])
    pq.write_table(pa.Table.from_arrays([pa.array(t), pa.array(v), pa.array(speed)],
                                        schema=schema), p)
    return ["v=volts", "omega=speed"]


def _wpilog(p, t, v, speed, unit):
    pytest.importorskip("wpiutil")
    import wpiutil
    from wpiutil.log import DoubleLogEntry

    w = wpiutil.DataLogWriter(str(p))
    a = DoubleLogEntry(w, "/v", 1)
    b = DoubleLogEntry(w, "/w", f'{{"unit": "{unit}"}}', 1)
    for k in range(N):
        a.append(float(v[k]), 1 + k * 1000)
        b.append(float(speed[k]), 1 + k * 1000)
    w.flush()
    del a, b, w
    return ["v=/v", "omega=/w"]


WRITERS = {".mf4": _mdf, ".tdms": _tdms, ".parquet": _parquet, ".wpilog": _wpilog}


@pytest.mark.parametrize("ext", list(WRITERS))
def test_stored_rpm_is_applied(tmp_path, ext):
    t, v, w = step_motor(5)
    p = tmp_path / f"log{ext}"
    mapping = WRITERS[ext](p, t, v, w * RPM, "rpm")
    log, said = _read(p, mapping)
    np.testing.assert_allclose(log["omega"], w, rtol=1e-9, atol=1e-9)  # before: w * 9.55
    assert any("converted by the unit the file stores" in m and "from rpm to rad/s" in m
               for m in said), said
    # a mapping with a scale is the whole conversion: not applied twice
    log, said = _read(p, [mapping[0], mapping[1] + "*rpm"])
    np.testing.assert_allclose(log["omega"], w, rtol=1e-9, atol=1e-9)
    assert not any("converted" in m for m in said), said


@pytest.mark.parametrize("ext", [".mf4", ".tdms"])
def test_stored_unit_of_another_quantity_is_refused(tmp_path, ext):
    """A tachometer channel in V mapped bare to omega: the values are volts, not rad/s."""
    t, v, w = step_motor(6)
    p = tmp_path / f"log{ext}"
    mapping = WRITERS[ext](p, t, v, w / 150, "V")
    with pytest.raises(LogError, match=r"is stored in V \(the file says so\), which is no speed: "
                                       r"give omega its scale to rad/s"):
        read_log(p, parse_mapping(mapping))


def test_unknown_stored_unit_is_said(tmp_path):
    t, v, w = step_motor(7)
    p = tmp_path / "log.tdms"
    mapping = _tdms(p, t, v, w, "counts/100ms")
    log, said = _read(p, mapping)
    np.testing.assert_array_equal(log["omega"], w)
    assert any("is stored in 'counts/100ms', a unit pmdcid does not convert" in m
               for m in said), said


def test_parquet_time_in_ms_by_its_metadata(tmp_path):
    """A Parquet time column whose field metadata says ms: before, refused ('t looks like
    milliseconds') or, for a slow log, read 1000 x too slow; now converted to s."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    t, v, w = step_motor(8)
    schema = pa.schema([pa.field("t", pa.float64(), metadata={"unit": "ms"}),
                        pa.field("v", pa.float64()), pa.field("omega", pa.float64())])
    p = tmp_path / "log.parquet"
    pq.write_table(pa.Table.from_arrays([pa.array(t * 1e3), pa.array(v), pa.array(w)],
                                        schema=schema), p)
    log, _ = _read(p, [])
    assert log.dt == pytest.approx(1e-3)
