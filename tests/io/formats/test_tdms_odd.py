"""TDMS files as LabVIEW and nptdms write them, beyond the plain waveform channel: each written
with nptdms, then read. A channel with no time of its own is one line, not an internal error."""

from __future__ import annotations

import numpy as np
import pytest
from read_util import STEP_N, run_cli, step_motor

N = STEP_N




@pytest.mark.parametrize("time_len", [None, N - 100])
def test_channel_without_time_is_one_line(tmp_path, time_len):
    """No waveform properties and no time channel (or one of another length): before, 'internal
    error TypeError: len() of unsized object'; now one line naming the signal and the fix."""
    nptdms = pytest.importorskip("nptdms")
    t, v, w = step_motor(1)
    chans = [nptdms.ChannelObject("data", "voltage", v), nptdms.ChannelObject("data", "speed", w)]
    if time_len is not None:
        chans.insert(0, nptdms.ChannelObject("data", "t", t[:time_len]))
    p = tmp_path / "log.tdms"
    with nptdms.TdmsWriter(p) as wr:
        wr.write_segment(chans)
    code, _, err = run_cli(["simulate", p, "-m", tmp_path / "m.json", "-o", tmp_path / "s.csv",
                         "-c", "v=data/voltage", "-c", "omega=data/speed"])
    assert code == 1 and len(err) == 1, err
    assert err[0].startswith(f"error: {p}: signal 'data/speed' has no time stamps of its own"), err
    assert "wf_increment" in err[0]


@pytest.mark.parametrize("how", ["wf_xunit_string", "time channel unit_string"])
def test_time_in_ms_by_the_file_s_own_words(tmp_path, how):
    """A waveform whose x unit is ms (wf_increment 1, wf_xunit_string 'ms'), or a time channel
    whose unit_string is 'ms': before, refused with 't looks like milliseconds ... map it with
    -c t=COLUMN*ms', a mapping a series file refuses ('carry their own time stamps'); now read
    in seconds."""
    nptdms = pytest.importorskip("nptdms")
    from pmdcid.io import parse_mapping, read_log

    t, v, w = step_motor(2)
    if how == "wf_xunit_string":
        wf = {"wf_increment": 1.0, "wf_start_offset": 0.0, "wf_xunit_string": "ms"}
        chans = [nptdms.ChannelObject("data", "voltage", v, properties=wf),
                 nptdms.ChannelObject("data", "speed", w, properties=wf)]
    else:
        chans = [nptdms.ChannelObject("data", "time", t * 1e3, properties={"unit_string": "ms"}),
                 nptdms.ChannelObject("data", "voltage", v),
                 nptdms.ChannelObject("data", "speed", w)]
    p = tmp_path / "log.tdms"
    with nptdms.TdmsWriter(p) as wr:
        wr.write_segment(chans)
    log = read_log(p, parse_mapping(["v=data/voltage", "omega=data/speed"]))
    assert log.dt == pytest.approx(1e-3) and log.n == N
    code, out, err = run_cli(["fit-mechanical", p, "-m", tmp_path / "m.json", "--km", "0.05",
                           "-c", "v=data/voltage", "-c", "omega=data/speed"])
    assert "looks like milliseconds" not in " ".join(err), err


def test_time_in_ms_not_said_by_the_file_names_a_fix_that_applies(tmp_path, monkeypatch):
    """A waveform in ms that does not say so (``wf_increment`` 1, no ``wf_xunit_string``):
    before, refused with 't looks like milliseconds ...: map it with -c t=COLUMN*ms', a mapping
    a series file refuses in turn ('carry their own time stamps'). Now the line says what a
    user of a TDMS file can do: write its time unit into the file (or --force)."""
    nptdms = pytest.importorskip("nptdms")
    from repo_paths import FIXTURES

    t, v, w = step_motor(3)
    wf = {"wf_increment": 1.0, "wf_start_offset": 0.0}
    monkeypatch.chdir(tmp_path)  # a short path: the line keeps its whole fix
    p = "log.tdms"
    with nptdms.TdmsWriter(p) as wr:
        wr.write_segment([nptdms.ChannelObject("data", "voltage", v, properties=wf),
                          nptdms.ChannelObject("data", "speed", w, properties=wf)])
    said = ("error: log.tdms: t looks like milliseconds (a sample period of 1; ms would make it "
            "0.001 s), and a .tdms file carries its own time: write wf_xunit_string 'ms' on its "
            "channels (unit_string on a time channel), which pmdcid reads")
    maps = ["-c", "v=data/voltage", "-c", "omega=data/speed"]
    code, _, err = run_cli(["fit-mechanical", p, "-m", "m.json", "--km", "0.05", *maps])
    assert code == 1 and err == [said + " (or --force to fit anyway)"], err
    code, _, err = run_cli(["plan", "--check", p, "-m", FIXTURES / "paper" / "truth.json",
                         "-o", "pl", *maps])
    assert code == 1 and err == [said], err
    wf["wf_xunit_string"] = "ms"  # the fix it names
    with nptdms.TdmsWriter(p) as wr:
        wr.write_segment([nptdms.ChannelObject("data", "voltage", v, properties=wf),
                          nptdms.ChannelObject("data", "speed", w, properties=wf)])
    code, _, err = run_cli(["fit-mechanical", p, "-m", "m.json", "--km", "0.05", *maps])
    assert not [e for e in err if "looks like" in e], err


def test_empty_channel_named_by_a_mapping_says_it_has_no_samples(tmp_path):
    """A channel written with 0 samples (a sensor that never delivered), named by ``-c``:
    before, 'no column 'data/speed' (columns are data/voltage)', as if the name were wrong,
    and ``channels`` did not list it. Now it is listed with 0 samples, and a mapping naming it
    is one line, exit 1, saying it is in the file but empty."""
    nptdms = pytest.importorskip("nptdms")
    _, v, _ = step_motor(4)
    wf = {"wf_increment": 1e-3, "wf_start_offset": 0.0}
    p = tmp_path / "log.tdms"
    with nptdms.TdmsWriter(p) as wr:
        wr.write_segment([nptdms.ChannelObject("data", "voltage", v, properties=wf),
                          nptdms.ChannelObject("data", "speed", np.array([], float),
                                               properties=wf)])
    code, out, _ = run_cli(["channels", p])
    assert code == 0 and [ln.split()[:2] for ln in out.splitlines()[1:]] == [
        ["data/voltage", str(N)], ["data/speed", "0"]], out
    code, _, err = run_cli(["fit-mechanical", p, "-m", tmp_path / "m.json", "--km", "0.05",
                         "-c", "v=data/voltage", "-c", "omega=data/speed*rpm"])
    assert code == 1 and err == [f"error: {p}: signal 'data/speed' is in the file but has 0 "
                                 "samples (nothing was recorded in it): map a signal that has "
                                 "samples, or record it again"], err
