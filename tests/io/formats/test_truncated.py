"""A log file cut short (a recorder that lost power, a copy that stopped) is never read silently:
each format written by its own library, then cut, then read. A wpilog (no footer: records one
after another) and a TDMS file of several segments are read to their last whole record /
segment with one warning saying how much was kept; a file with nothing whole before the cut,
an MCAP, Parquet or MATLAB file cut short is refused in one line that says so."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pmdcid.cli import main

N = 600
T = np.arange(N) * 1e-3


def _channels(path):
    res = CliRunner().invoke(main, ["channels", str(path)])
    return res.exit_code, res.stdout, res.stderr.strip().splitlines()


def _cut(whole, cut, keep):
    data = whole.read_bytes()
    cut.write_bytes(data[:keep if keep >= 0 else len(data) + keep])
    return len(data)


def _samples(stdout, name):
    row = next(r for r in stdout.splitlines() if r.startswith(name + " "))
    return int(row.split()[1])


def _write_tdms(path, segments):
    from nptdms import ChannelObject, TdmsWriter

    wf = {"wf_increment": 1e-3, "wf_start_offset": 0.0}
    with TdmsWriter(path) as w:
        for part in np.array_split(np.arange(N), segments):
            w.write_segment([ChannelObject("drive", "voltage", np.sin(T[part]), properties=wf),
                             ChannelObject("encoder", "speed", T[part], properties=wf)])


def test_tdms_cut_in_its_only_segment_is_refused(tmp_path):
    pytest.importorskip("nptdms")
    _write_tdms(tmp_path / "w.tdms", 1)
    _cut(tmp_path / "w.tdms", tmp_path / "log.tdms", -100)
    code, out, err = _channels(tmp_path / "log.tdms")
    assert code == 1 and len(err) == 1, err  # before: exit 0, speed 588 samples of 600
    assert err[0].startswith(f"error: {tmp_path / 'log.tdms'}: the TDMS file is cut short "
                             "(100 bytes of its first segment missing): it was not closed")


def test_tdms_cut_in_its_last_segment_keeps_the_whole_ones(tmp_path):
    pytest.importorskip("nptdms")
    _write_tdms(tmp_path / "w.tdms", 3)
    size = _cut(tmp_path / "w.tdms", tmp_path / "log.tdms", -100)
    code, out, err = _channels(tmp_path / "log.tdms")
    assert code == 0 and len(err) == 1, err
    assert err[0].startswith(f"warning: {tmp_path / 'log.tdms'}: the TDMS file is cut short "
                             "(100 bytes of a segment missing)")
    assert "read its 2 whole segments" in err[0] and f"of {size - 100} bytes" in err[0]
    assert _samples(out, "drive/voltage") == _samples(out, "encoder/speed") == 400


def _write_wpilog(path):
    import wpiutil
    from wpiutil.log import DoubleLogEntry

    w = wpiutil.DataLogWriter(str(path))
    v, s = DoubleLogEntry(w, "/drive/voltage", 1), DoubleLogEntry(w, "/drive/speed", 1)
    for k in range(N):
        v.append(float(np.sin(T[k])), 1 + k * 1000)
        s.append(float(T[k]), 1 + k * 1000)
    w.flush()
    del v, s, w


def test_wpilog_cut_in_a_record_is_read_to_the_last_whole_one(tmp_path):
    pytest.importorskip("wpiutil")
    _write_wpilog(tmp_path / "w.wpilog")
    _cut(tmp_path / "w.wpilog", tmp_path / "log.wpilog", -3)  # in the last record
    code, out, err = _channels(tmp_path / "log.wpilog")
    assert code == 0 and len(err) == 1, err  # before: no word
    assert err[0].startswith(f"warning: {tmp_path / 'log.wpilog'}: the .wpilog file is cut "
                             "short (3 bytes of its last record missing: it was not closed")
    assert _samples(out, "/drive/voltage") == N and _samples(out, "/drive/speed") == N - 1


def test_wpilog_cut_before_any_whole_record_is_refused(tmp_path):
    pytest.importorskip("wpiutil")
    _write_wpilog(tmp_path / "w.wpilog")
    _cut(tmp_path / "w.wpilog", tmp_path / "log.wpilog", 20)
    code, out, err = _channels(tmp_path / "log.wpilog")
    assert code == 1 and len(err) == 1, err
    assert "the .wpilog file is cut short" in err[0] and "holds no whole record" in err[0]


def _write_mcap(path):
    import json

    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(name="m", encoding="jsonschema", data=b"{}")
        ch = w.register_channel(topic="/motor", message_encoding="json", schema_id=sid)
        for k in range(N):
            ns = int(T[k] * 1e9)
            w.add_message(ch, log_time=ns, publish_time=ns,
                          data=json.dumps({"v": float(np.sin(T[k]))}).encode())
        w.finish()


def _write_parquet(path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    pq.write_table(pa.table({"t": T, "v": np.sin(T)}), path)


def _write_mat5(path):
    import scipy.io

    scipy.io.savemat(path, {"t": T, "v": np.sin(T)})


def _write_mat73(path):
    h5py = pytest.importorskip("h5py")
    with h5py.File(path, "w") as fh:
        fh["t"], fh["v"] = T[:, None], np.sin(T)[:, None]


@pytest.mark.parametrize("name, write, said", [
    ("log.mcap", _write_mcap, "the MCAP file is cut short"),
    ("log.parquet", _write_parquet, "the Parquet file is cut short"),
    ("log.mat", _write_mat5, "the MATLAB file is cut short"),
    ("log73.mat", _write_mat73, "the MATLAB v7.3 (HDF5) file is cut short"),
])
@pytest.mark.parametrize("where", ["half", "end"])
def test_a_cut_file_with_a_footer_or_sizes_is_refused_in_one_line(tmp_path, name, write, said,
                                                                  where):
    whole = tmp_path / ("whole" + name[name.index("."):])
    write(whole)
    size = whole.stat().st_size
    _cut(whole, tmp_path / name, size // 2 if where == "half" else -7)
    code, out, err = _channels(tmp_path / name)
    assert code == 1 and len(err) == 1 and out == "", (out, err)
    assert err[0].startswith(f"error: {tmp_path / name}: {said}"), err
