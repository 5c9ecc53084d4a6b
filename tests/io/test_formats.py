"""io/formats: each format written by its own library from a synthetic log, read back, and the
same motor identified from it as from the CSV (fit-mechanical, parameters within 0.5 %; the
same samples give the same numbers). Signals on different clocks; `pmdcid channels`."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

from pmdcid.cli import main
from pmdcid.errors import LogError, MappingError
from pmdcid.io import Log, parse_mapping, read_log, write_log
from pmdcid.io.formats import channels
from pmdcid.model import Model
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, step, synth_log

RATE = 1000.0
AMPLITUDES = (1.0, 2.0)


@pytest.fixture(scope="module")
def truth():
    vals = {**neutral_values(), **PAPER}
    vals.update(J=PAPER["J"] * 1.15, bv=PAPER["bv"] * 0.9)
    return vals


@pytest.fixture(scope="module")
def logs(truth):
    """Two noisy free-speed steps (1.5 s at 1 kHz): name -> (t, columns)."""
    rng = np.random.default_rng(2701)
    t = np.arange(int(1.5 * RATE)) / RATE
    out = {}
    for a in AMPLITUDES:
        cols, _ = synth_log(t, step(t, a, 0.2), truth, PAPER_NOISE, rng)
        out[f"step_{a:g}V"] = (t, cols)
    return out


def _model(truth) -> Model:
    m = Model()
    for k in ("R", "L", "km"):
        m.set(k, truth[k], stage="truth")
    return m


def _fit(paths, truth, mapping=()):
    from pmdcid.identify.mechanical import fit_mechanical

    read = [read_log(p, parse_mapping(list(mapping))) for p in paths]
    res = fit_mechanical(read, _model(truth))
    return {k: res.estimates[k].value for k in ("J", "bv", "bc")}, read


@pytest.fixture(scope="module")
def csv_fit(logs, truth, tmp_path_factory):
    d = tmp_path_factory.mktemp("csv")
    paths = []
    for name, (t, cols) in logs.items():
        paths.append(d / f"{name}.csv")
        write_log(paths[-1], t, cols)
    return _fit(paths, truth)


# --- writers: each format by its own library ---------------------------------------------

def write_parquet(path, t, cols):
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = [pa.field("time", pa.float64()), pa.field("volts", pa.float64(), {"unit": "V"}),
              pa.field("current", pa.float64(), {"unit": "A"}),
              pa.field("speed", pa.float64(), {"unit": "rad/s"})]
    table = pa.table([t, cols["v"], cols["i"], cols["omega"]], schema=pa.schema(fields))
    pq.write_table(table, path)
    return ["t=time", "v=volts", "i=current", "omega=speed"]


def write_mat5(path, t, cols):
    import scipy.io

    scipy.io.savemat(path, {"log": {"t": t, "v": cols["v"], "i": cols["i"],
                                    "w": cols["omega"]}})
    return ["t=log.t", "v=log.v", "i=log.i", "omega=log.w"]


def write_mat73(path, t, cols):
    """A MATLAB v7.3 file as MATLAB writes one: a 512-byte header, then HDF5 with each
    variable a 1 x N double (stored N x 1: MATLAB is column-major) and a struct as a group."""
    import h5py

    with h5py.File(path, "w", userblock_size=512) as fh:
        g = fh.create_group("log")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, x in (("t", t), ("v", cols["v"]), ("i", cols["i"]), ("w", cols["omega"])):
            ds = g.create_dataset(name, data=np.asarray(x, float)[:, None])
            ds.attrs["MATLAB_class"] = np.bytes_("double")
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2026 HDF5"
    with open(path, "r+b") as fh:
        fh.write(head.ljust(116) + b"\x00" * 8 + b"\x00\x02IM")
    return ["t=log.t", "v=log.v", "i=log.i", "omega=log.w"]


def write_tdms(path, t, cols):
    from nptdms import ChannelObject, TdmsWriter

    wf = {"wf_increment": float(t[1] - t[0]), "wf_start_offset": 0.0}
    with TdmsWriter(path) as w:
        w.write_segment([
            ChannelObject("drive", "voltage", cols["v"], properties={**wf, "unit_string": "V"}),
            ChannelObject("drive", "current", cols["i"], properties={**wf, "unit_string": "A"}),
            ChannelObject("encoder", "speed", cols["omega"],
                          properties={**wf, "unit_string": "rad/s"})])
    return ["v=drive/voltage", "i=drive/current", "omega=encoder/speed"]


def write_mdf(path, t, cols):
    from asammdf import MDF, Signal

    m = MDF(version="4.10")
    m.append([Signal(cols["v"], t, name="u_arm", unit="V"),
              Signal(cols["i"], t, name="i_arm", unit="A"),
              Signal(cols["omega"], t, name="n_mot", unit="rad/s")], acq_name="motor")
    m.save(path, overwrite=True)
    m.close()
    return ["v=u_arm", "i=i_arm", "omega=n_mot"]


def write_mcap_ros2(path, t, cols):
    from mcap_ros2.writer import Writer

    joint = ("std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n"
             "float64[] effort\n" + "=" * 80 + "\nMSG: std_msgs/Header\n"
             "builtin_interfaces/Time stamp\nstring frame_id\n" + "=" * 80 +
             "\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec")
    with open(path, "wb") as fh:
        w = Writer(fh)
        js = w.register_msgdef("sensor_msgs/msg/JointState", joint)
        f64 = w.register_msgdef("std_msgs/msg/Float64", "float64 data")
        for k in range(len(t)):
            ns = int(round(t[k] * 1e9))
            stamp = {"sec": ns // 10**9, "nanosec": ns % 10**9}
            w.write_message("/cmd_voltage", f64, {"data": float(cols["v"][k])}, log_time=ns,
                            publish_time=ns)
            w.write_message("/joint_states", js, {
                "header": {"stamp": stamp, "frame_id": ""}, "name": ["motor"],
                "position": [0.0], "velocity": [float(cols["omega"][k])],
                "effort": [float(cols["i"][k])]}, log_time=ns, publish_time=ns)
        w.finish()
    return ["v=/cmd_voltage.data", "omega=/joint_states.velocity", "i=/joint_states.effort"]


def write_mcap_json(path, t, cols):
    from mcap.writer import Writer

    with open(path, "wb") as fh:
        w = Writer(fh)
        w.start()
        sid = w.register_schema(name="motor.State", encoding="jsonschema", data=b"{}")
        ch = w.register_channel(topic="/motor/state", message_encoding="json", schema_id=sid)
        for k in range(len(t)):
            ns = int(round(t[k] * 1e9))
            msg = {"voltage": float(cols["v"][k]), "current": float(cols["i"][k]),
                   "velocity": float(cols["omega"][k])}
            w.add_message(ch, log_time=ns, publish_time=ns, data=json.dumps(msg).encode())
        w.finish()
    return ["v=/motor/state.voltage", "i=/motor/state.current",
            "omega=/motor/state.velocity"]


def write_wpilog(path, t, cols):
    import wpiutil
    from wpiutil.log import DoubleLogEntry

    w = wpiutil.DataLogWriter(str(path))
    entries = {"v": DoubleLogEntry(w, "/drive/voltage", '{"unit": "V"}', 1),
               "i": DoubleLogEntry(w, "/drive/current", 1),
               "omega": DoubleLogEntry(w, "/drive/speed", 1)}
    for k in range(len(t)):
        us = 1 + int(round(t[k] * 1e6))  # 0 means "now" to the writer
        for c, e in entries.items():
            e.append(float(cols[c][k]), us)
    w.flush()
    del entries, w
    return ["v=/drive/voltage", "i=/drive/current", "omega=/drive/speed"]


WRITERS = {".parquet": write_parquet, "-v5.mat": write_mat5, "-v73.mat": write_mat73,
           ".tdms": write_tdms, ".mf4": write_mdf, "-ros2.mcap": write_mcap_ros2,
           "-json.mcap": write_mcap_json, ".wpilog": write_wpilog}


@pytest.mark.parametrize("suffix", list(WRITERS))
def test_same_motor_as_from_the_csv(suffix, logs, truth, csv_fit, tmp_path):
    paths, mapping = [], []
    for name, (t, cols) in logs.items():
        paths.append(tmp_path / f"{name}{suffix}")
        mapping = WRITERS[suffix](paths[-1], t, cols)
    got, read = _fit(paths, truth, mapping)
    ref, ref_logs = csv_fit
    for lg, rl in zip(read, ref_logs, strict=True):
        assert lg.n == rl.n and lg.dt == pytest.approx(rl.dt, rel=1e-9)
        for c in ("v", "i", "omega"):  # CSV keeps 9 significant digits
            np.testing.assert_allclose(lg[c], rl[c], rtol=1e-8, atol=1e-12)
        assert not lg.notes  # one clock: nothing interpolated, nothing said
    for k, v in ref.items():
        assert got[k] == pytest.approx(v, rel=0.005), k
        assert got[k] == pytest.approx(truth[k], rel=0.03), k  # and the truth, within noise


def test_signals_on_different_clocks(logs, truth, csv_fit, tmp_path):
    """Speed logged by its own topic 0.4 ms after each command, at half the rate: put on the
    voltage's clock (held input, speed interpolated), said in one line; the same motor within
    1 % (interpolating a 2 ms-spaced speed costs at most (h/tau)^2/8 ~ 0.005 % of a step)."""
    from mcap.writer import Writer

    paths = []
    for name, (t, cols) in logs.items():
        paths.append(tmp_path / f"{name}.mcap")
        with open(paths[-1], "wb") as fh:
            w = Writer(fh)
            w.start()
            sid = w.register_schema(name="x", encoding="jsonschema", data=b"{}")
            cmd = w.register_channel(topic="/cmd", message_encoding="json", schema_id=sid)
            enc = w.register_channel(topic="/enc", message_encoding="json", schema_id=sid)
            for k in range(len(t)):
                ns = int(round(t[k] * 1e9))
                w.add_message(cmd, log_time=ns, publish_time=ns,
                              data=json.dumps({"volts": float(cols["v"][k])}).encode())
                if k % 2 == 0:
                    w.add_message(enc, log_time=ns + 400_000, publish_time=ns, data=json.dumps(
                        {"omega": float(np.interp(t[k] + 4e-4, t, cols["omega"]))}).encode())
            w.finish()
    with pytest.warns(UserWarning, match="signals on different clocks put on the input's clock"):
        got, read = _fit(paths, truth, ["v=/cmd.volts", "omega=/enc.omega"])
    assert read[0].notes and "'/cmd.volts', 1000 Hz" in read[0].notes[0]
    assert read[0].t_file[0] == pytest.approx(1e-3)  # the first command once the speed runs
    for k, v in csv_fit[0].items():
        assert got[k] == pytest.approx(v, rel=0.01), k


def test_loop_timed_input_clock_in_a_series_file(tmp_path, rng):
    """A wpilog whose loop logs when it runs (4-18 ms): the input's clock is resampled onto a
    uniform grid as a loop-timed CSV is, in the same step as the other clocks."""
    import wpiutil
    from wpiutil.log import DoubleLogEntry

    t = np.cumsum(rng.uniform(0.004, 0.018, 300))
    p = tmp_path / "loop.wpilog"
    w = wpiutil.DataLogWriter(str(p))
    ev, eo = DoubleLogEntry(w, "/v", 1), DoubleLogEntry(w, "/w", 1)
    for k, tk in enumerate(t):
        ev.append(1.0 if k > 20 else 0.0, int(tk * 1e6))
        eo.append(float(k), int(tk * 1e6) + 500)
    w.flush()
    del ev, eo, w
    log = read_log(p, parse_mapping(["v=/v", "omega=/w"]))
    same = Log.from_file(p, columns={"v": "/v", "omega": "/w"})
    assert np.array_equal(same["omega"], log["omega"])
    assert log.resampled is not None
    assert "signals on different clocks" in log.notes[0] and "loop-timed" in log.notes[0]
    assert log.dt == pytest.approx(np.median(np.diff(t)), rel=0.01)


def test_channels_lists_names_samples_rates_units(logs, tmp_path):
    t, cols = logs["step_1V"]
    p = tmp_path / "a.mf4"
    write_mdf(p, t, cols)
    got = {c.name: c for c in channels(p)}
    assert set(got) == {"u_arm", "i_arm", "n_mot"}
    assert got["n_mot"].samples == len(t) and got["n_mot"].unit == "rad/s"
    assert got["n_mot"].rate == pytest.approx(RATE)
    res = CliRunner().invoke(main, ["channels", str(p)])
    assert res.exit_code == 0 and "n_mot" in res.output and "rad/s" in res.output
    csv = tmp_path / "a.csv"
    write_log(csv, t, cols)
    res = CliRunner().invoke(main, ["channels", str(csv), "--json"])
    listed = json.loads(res.output)
    assert [c["name"] for c in listed] == ["t", "v", "i", "omega", "theta"]
    assert listed[0]["rate_hz"] == pytest.approx(RATE) and listed[0]["samples"] == len(t)


def test_missing_reader_names_the_extra(tmp_path, monkeypatch):
    import sys

    for mod in ("mcap", "mcap.reader"):
        monkeypatch.setitem(sys.modules, mod, None)  # as if not installed: import fails
    p = tmp_path / "x.mcap"
    p.write_bytes(b"\x89MCAP0\r\n")
    res = CliRunner().invoke(main, ["channels", str(p)])
    assert res.exit_code == 1
    assert res.output == (f"error: {p}: reading .mcap files needs the package 'mcap': "
                          "pip install 'pmdcid[mcap]'\n")


@pytest.mark.parametrize("ext", [".mcap", ".wpilog", ".mf4", ".mdf", ".tdms", ".mat",
                                 ".parquet"])
@pytest.mark.parametrize("content", [b"", b"hello\n", "random"])
def test_broken_file_is_one_line(tmp_path, ext, content):
    """Empty, text or random bytes under each extension: one line naming the file, exit 1."""
    if content == "random":
        content = np.random.default_rng(7).bytes(3000)
    p = tmp_path / f"bad{ext}"
    p.write_bytes(content)
    for args in (["channels", str(p)], ["simulate", str(p), "-m", "m.json", "-o", "o.csv"]):
        res = CliRunner().invoke(main, args)
        assert res.exit_code == 1, res.output
        assert res.output.startswith(f"error: {p}: ") and res.output.count("\n") == 1
        assert "internal error" not in res.output


def test_unmapped_series_file_says_how_to_map(logs, tmp_path):
    t, cols = logs["step_1V"]
    p = tmp_path / "a.wpilog"
    write_wpilog(p, t, cols)
    with pytest.raises(LogError, match=r"no signal is mapped.*-c v=SOURCE.*pmdcid channels"):
        read_log(p)
    with pytest.raises(LogError, match=r"carry their own time stamps"):
        read_log(p, parse_mapping(["t=/drive/voltage", "v=/drive/voltage"]))


def test_slashed_names_in_mappings(tmp_path):
    """A name holding '/' is read whole (the longest signal name the right-hand side starts
    with), the rest is its scale and offset; a CSV mapping with '/' as a divisor is unchanged."""
    from pmdcid.io.mapping import parse_spec, resolve

    spec = resolve(parse_spec("v=drive/pwm/255*12"), ["drive/pwm", "drive/dir"])
    assert (spec.source, spec.scale, spec.offset) == ("drive/pwm", pytest.approx(12 / 255), 0.0)
    spec = resolve(parse_spec("omega=/joint_states.velocity*rpm+1"), ["/joint_states.velocity"])
    assert spec.source == "/joint_states.velocity"
    assert spec.scale == pytest.approx(2 * np.pi / 60) and spec.offset == 1.0
    assert parse_spec("v=pwm*12/1023").scale == pytest.approx(12 / 1023)
    # a file whose names hold '/': a name of that kind it lacks (the reader lists its names)
    spec = resolve(parse_spec("omega=enc/omega*rpm"), ["drive/omega"])
    assert (spec.source, spec.scale) == ("enc/omega", pytest.approx(2 * np.pi / 60))
    # a file whose names hold none: '/' divides, and what follows is no number
    with pytest.raises(MappingError, match="'omega' is neither a number nor a unit"):
        resolve(parse_spec("omega=enc/omega"), ["enc", "omega"])
    with pytest.raises(MappingError, match="'\\*rpmm' after 'drive/omega' is not a scale"):
        resolve(parse_spec("omega=drive/omega*rpmm"), ["drive/omega"])


#: a signal the file does not hold, named as the format names them (with a scale)
ABSENT = {".tdms": ("omega=encoder/nosuch*rpm", "encoder/speed"),
          "-json.mcap": ("omega=/motor/state.nosuch", "/motor/state.velocity"),
          "-ros2.mcap": ("omega=/joint_states.nosuch*rpm", "/joint_states.velocity"),
          ".wpilog": ("omega=/drive/nosuch*rpm", "/drive/speed"),
          ".mf4": ("omega=nosuch*rpm", "n_mot")}


@pytest.mark.parametrize("suffix", list(ABSENT))
def test_absent_signal_is_the_file_s_problem(suffix, logs, tmp_path):
    """A well-formed -c naming a signal the file does not hold is exit 1, one line naming the
    file and listing its signals (a '/' in it was 'neither a number nor a unit', exit 2); a
    scale that does not parse stays a usage error (exit 2)."""
    t, cols = logs["step_1V"]
    p = tmp_path / f"log{suffix}"
    mapping = WRITERS[suffix](p, t[:200], {k: c[:200] for k, c in cols.items()})
    v = next(m for m in mapping if m.startswith("v="))
    bad, listed = ABSENT[suffix]
    args = ["fit-mechanical", str(p), "-m", str(tmp_path / "m.json"), "-c", v, "-c"]
    res = CliRunner().invoke(main, [*args, bad])
    assert res.exit_code == 1, res.output
    assert res.output.startswith(f"error: {p}: ") and res.output.count("\n") == 1
    assert "no column" in res.output and listed in res.output, res.output
    res = CliRunner().invoke(main, [*args, f"omega={listed}*rpmm"])
    assert res.exit_code == 2 and "rpmm' " in res.output, res.output


def _wpilog(path, entries):
    """A wpilog of ``{name: (times [s], values)}``, each entry logged at its own instants."""
    import wpiutil
    from wpiutil.log import DoubleLogEntry

    w = wpiutil.DataLogWriter(str(path))
    made = {name: DoubleLogEntry(w, name, 1) for name in entries}
    rows = sorted((int(round(tk * 1e6)) + 1, name, float(x))
                  for name, (ts, xs) in entries.items() for tk, x in zip(ts, xs, strict=True))
    for us, name, x in rows:
        made[name].append(x, us)
    w.flush()
    del made, w


def test_input_logged_when_it_changes(logs, truth, csv_fit, tmp_path):
    """A command logged only when it changes (twice: 0 V, then the step), the speed every ms:
    the input is held across its gaps on the speed's 1 kHz grid; the same motor as the CSV."""
    paths = []
    for name, (t, cols) in logs.items():
        change = np.flatnonzero(np.diff(cols["v"])) + 1
        at = np.concatenate(([0], change))
        paths.append(tmp_path / f"{name}.wpilog")
        _wpilog(paths[-1], {"/cmd": (t[at], cols["v"][at]), "/speed": (t, cols["omega"])})
    with pytest.warns(UserWarning, match=r"uniform 1000 Hz grid, the fastest measurement's"):
        got, read = _fit(paths, truth, ["v=/cmd", "omega=/speed"])
    ref_logs = csv_fit[1]
    assert read[0].n == ref_logs[0].n
    np.testing.assert_allclose(read[0]["v"], ref_logs[0]["v"], atol=1e-9)
    for k, v in csv_fit[0].items():
        assert got[k] == pytest.approx(v, rel=0.005), k


def test_slow_command_fast_encoder(logs, tmp_path):
    """A 50 Hz command and a 1 kHz speed: the grid is the speed's (the input held on it), not
    the command's 50 Hz, which would throw away 19 speed samples in 20."""
    t, cols = logs["step_2V"]
    slow = np.arange(0, len(t), 20)
    p = tmp_path / "slow.wpilog"
    _wpilog(p, {"/cmd": (t[slow], cols["v"][slow]), "/speed": (t, cols["omega"])})
    log = read_log(p, parse_mapping(["v=/cmd", "omega=/speed"]))
    assert log.dt == pytest.approx(1e-3) and log.n == len(t)
    assert "the input '/cmd' (50 Hz) held on it" in log.notes[0]
    np.testing.assert_allclose(log["omega"], cols["omega"], rtol=1e-9, atol=1e-12)
