"""TDMS files as LabVIEW and nptdms write them, beyond the plain waveform channel: each written
with nptdms, then read. A channel with no time of its own is one line, not an internal error."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from pmdcid.cli import main

N = 400


def _motor(seed):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 1e-3
    v = np.where(t >= 0.1, 6.0, 0.0)
    w = np.where(t >= 0.1, 20.0 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.1)), 0.0)
    return t, v, w + rng.normal(0, 0.02, N)


def _run(args):
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.stdout, res.stderr.strip().splitlines()


@pytest.mark.parametrize("time_len", [None, N - 100])
def test_channel_without_time_is_one_line(tmp_path, time_len):
    """No waveform properties and no time channel (or one of another length): before, 'internal
    error TypeError: len() of unsized object'; now one line naming the signal and the fix."""
    nptdms = pytest.importorskip("nptdms")
    t, v, w = _motor(1)
    chans = [nptdms.ChannelObject("data", "voltage", v), nptdms.ChannelObject("data", "speed", w)]
    if time_len is not None:
        chans.insert(0, nptdms.ChannelObject("data", "t", t[:time_len]))
    p = tmp_path / "log.tdms"
    with nptdms.TdmsWriter(p) as wr:
        wr.write_segment(chans)
    code, _, err = _run(["simulate", p, "-m", tmp_path / "m.json", "-o", tmp_path / "s.csv",
                         "-c", "v=data/voltage", "-c", "omega=data/speed"])
    assert code == 1 and len(err) == 1, err
    assert err[0].startswith(f"error: {p}: signal 'data/speed' has no time stamps of its own"), err
    assert "wf_increment" in err[0]
