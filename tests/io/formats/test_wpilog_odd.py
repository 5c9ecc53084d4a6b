"""A .wpilog written as WPILib's SysIdRoutineLog writes it: entries ``voltage-<motor>-<mech>``,
``position-...``, ``velocity-...`` whose metadata is the unit's plain name (``Volts.name()`` =
"Volt", ``Rotations.name()`` = "Rotation", ``RotationsPerSecond.name()`` = "Rotation per
Second"), not JSON. Before, the reader dropped such metadata: ``channels`` showed no unit and a
bare ``-c omega=velocity-shooter-Shooter`` read rotations per second as rad/s (J and bv 2 pi
off, exit 0, no word). Now the unit is read and applied, with the warning other formats give."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from pmdcid.cli import main
from pmdcid.io import parse_mapping, read_log

N = 400


def _sysid_log(p):
    pytest.importorskip("wpiutil")
    import wpiutil
    from wpiutil.log import DoubleLogEntry, StringLogEntry

    rng = np.random.default_rng(3)
    t = np.arange(N) * 0.02
    v = np.where(t >= 0.5, 7.0, 0.0)
    rps = np.where(t >= 0.5, 50.0 * (1 - np.exp(-np.clip(t - 0.5, 0, None) / 0.4)), 0.0)
    rps = rps + rng.normal(0, 0.05, N)
    rot = np.cumsum(rps) * 0.02
    w = wpiutil.DataLogWriter(str(p))
    ev = DoubleLogEntry(w, "voltage-shooter-Shooter", "Volt")
    ep = DoubleLogEntry(w, "position-shooter-Shooter", "Rotation")
    es = DoubleLogEntry(w, "velocity-shooter-Shooter", "Rotation per Second")
    st = StringLogEntry(w, "sysid-test-state-Shooter")
    st.append("dynamic-forward", 1)
    for k in range(N):
        us = 1 + k * 20000
        ev.append(float(v[k]), us)
        ep.append(float(rot[k]), us)
        es.append(float(rps[k]), us)
    w.flush()
    del ev, ep, es, st, w
    return v, rps, rot


def test_sysid_plain_unit_names_are_read_and_applied(tmp_path):
    p = tmp_path / "sysid.wpilog"
    v, rps, rot = _sysid_log(p)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        log = read_log(p, parse_mapping(["v=voltage-shooter-Shooter",
                                         "omega=velocity-shooter-Shooter",
                                         "theta=position-shooter-Shooter"]))
    said = [str(w.message) for w in caught]
    np.testing.assert_allclose(log["omega"], rps * 2 * np.pi, rtol=1e-9)   # before: rps
    np.testing.assert_allclose(log["theta"], rot * 2 * np.pi, rtol=1e-9)
    np.testing.assert_allclose(log["v"], v)
    assert any("from Rotation per Second to rad/s (x 6.28319) as omega" in m for m in said), said
    # a scale given is the whole conversion: not applied twice
    log = read_log(p, parse_mapping(["v=voltage-shooter-Shooter",
                                     "omega=velocity-shooter-Shooter*rps"]))
    np.testing.assert_allclose(log["omega"], rps * 2 * np.pi, rtol=1e-9)


def test_channels_lists_the_plain_unit(tmp_path):
    p = tmp_path / "sysid.wpilog"
    _sysid_log(p)
    r = CliRunner().invoke(main, ["channels", str(p), "--json"])
    assert r.exit_code == 0, r.output
    units = {c["name"]: c["unit"] for c in json.loads(r.output)}
    assert units["velocity-shooter-Shooter"] == "Rotation per Second"
    assert units["voltage-shooter-Shooter"] == "Volt"
    assert "sysid-test-state-Shooter" not in units   # a string entry is no signal
