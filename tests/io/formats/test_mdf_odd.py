"""MDF files as a test bench writes them, beyond one group of uniquely named channels: each
written with asammdf, then read."""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner
from read_util import step_motor

from pmdcid.cli import main


def test_unique_channel_named_by_its_group(tmp_path):
    """docs/io.md: '-c omega=motor/n_mot names the same channel by its group'. Before, that
    mapping (with or without a scale) was a usage error, exit 2: "'n_mot' is neither a number
    nor a unit"; now it reads the channel, its scale applied."""
    asammdf = pytest.importorskip("asammdf")
    from pmdcid.io import parse_mapping, read_log

    t, v, w = step_motor(11)
    p = tmp_path / "bench.mf4"
    m = asammdf.MDF(version="4.10")
    m.append([asammdf.Signal(v, t, name="u_arm"),
              asammdf.Signal(w * 60 / (2 * np.pi), t, name="n_mot")], acq_name="motor")
    m.save(p, overwrite=True)
    m.close()
    log = read_log(p, parse_mapping(["v=motor/u_arm", "omega=motor/n_mot*rpm"]))
    np.testing.assert_allclose(log["omega"], w, rtol=1e-9, atol=1e-9)
    np.testing.assert_array_equal(log["v"], v)
    res = CliRunner().invoke(main, ["simulate", str(p), "-m", str(tmp_path / "m.json"), "-o",
                                    str(tmp_path / "s.csv"), "-c", "v=u_arm", "-c",
                                    "omega=-motor/n_mot*rpm"])
    assert res.exit_code == 1, res.output  # the model file is missing: past the mapping
    assert "no such model file" in res.stderr, res.stderr


def _mdf_bytes(tmp_path):
    asammdf = pytest.importorskip("asammdf")
    t, v, w = step_motor(12)
    p = tmp_path / "w.mf4"
    m = asammdf.MDF(version="4.10")
    m.append([asammdf.Signal(v, t, name="u_arm"), asammdf.Signal(w, t, name="n_mot")])
    m.save(p, overwrite=True)
    m.close()
    return p.read_bytes()


def test_file_under_the_wrong_extension_says_what_it_is(tmp_path):
    """An MDF file named .csv: before, 'is not a text CSV file (binary content): export the log
    as CSV' (it needs only its name); an MDF named .tdms: 'is not a readable TDMS file (Segment
    does not start with b'TDSm' ...)'; a CSV named .mf4: 'is not a readable MDF file
    (MdfException: ... magic)'; an empty .mf4: '... magic head'. Now each says what the file is
    and the name that reads it."""
    data = _mdf_bytes(tmp_path)
    t, v, w = step_motor(13)
    text = "t,v,omega\n" + "".join(f"{a},{b},{c}\n" for a, b, c in zip(t, v, w, strict=True))
    cases = {"log.csv": (data, "is an ASAM MDF file (its first bytes say so), not CSV text: "
                               "name it .mf4 to read it"),
             "log.tdms": (data, "is an ASAM MDF file (its first bytes say so), not a .tdms "
                                "file: name it .mf4 to read it"),
             "csv.mf4": (text.encode(), "is text (its first line 't,v,omega'), not a .mf4 file: "
                                        "a CSV log? name it .csv to read it"),
             "empty.mf4": (b"", "is empty (0 bytes): no .mf4 file was written into it")}
    for name, (content, said) in cases.items():
        p = tmp_path / name
        p.write_bytes(content)
        res = CliRunner().invoke(main, ["channels", str(p)])
        assert res.exit_code == 1 and res.stderr == f"error: {p}: {said}\n", res.stderr


@pytest.mark.parametrize("name", ["speed", "motor/speed", "speed*rpm", "motor/speed*rpm"])
def test_empty_channel_group_named_by_a_mapping_says_it_has_no_samples(tmp_path, name):
    """A channel group with 0 samples (a measurement started, never triggered), its channel
    named by ``-c``: before, 'no column 'speed' (columns are u_arm)', or for ``motor/speed`` a
    usage error, exit 2: "'speed' is neither a number nor a unit". Now one line, exit 1: the
    signal is in the file but has 0 samples."""
    asammdf = pytest.importorskip("asammdf")
    t, v, _ = step_motor(14)
    p = tmp_path / "bench.mf4"
    m = asammdf.MDF(version="4.10")
    m.append([asammdf.Signal(v, t, name="u_arm")], acq_name="drive")
    m.append([asammdf.Signal(np.array([], float), np.array([], float), name="speed")],
             acq_name="motor")
    m.save(p, overwrite=True)
    m.close()
    res = CliRunner().invoke(main, ["fit-mechanical", str(p), "-m", str(tmp_path / "m.json"),
                                    "--km", "0.05", "-c", "v=u_arm", "-c", f"omega={name}"])
    assert res.exit_code == 1 and res.stderr.splitlines() == [
        f"error: {p}: signal 'speed' is in the file but has 0 samples (nothing was recorded in "
        "it): map a signal that has samples, or record it again"], res.stderr
