"""Log reading, column mapping and the model file (normal paths; bad inputs in test_bad_inputs)."""

import json
import math

import numpy as np
import pytest

from pmdcid.errors import LogError, ModelError
from pmdcid.io import parse_mapping, read_log, write_log
from pmdcid.io.mapping import is_setpoint, parse_spec
from pmdcid.model import Model, load_model, save_model


def test_mapping_syntax():
    s = parse_spec("omega=speed_rpm*rpm")
    assert (s.canon, s.source) == ("omega", "speed_rpm")
    assert s.scale == pytest.approx(2 * math.pi / 60)
    s = parse_spec("theta = enc*2*pi/4096")
    assert s.scale == pytest.approx(2 * math.pi / 4096)
    s = parse_spec("i=current_mA*mA-0.002")
    assert s.scale == pytest.approx(1e-3) and s.offset == pytest.approx(-0.002)
    s = parse_spec("v=pwm*12/1023+0.5")
    assert s.scale == pytest.approx(12 / 1023) and s.offset == pytest.approx(0.5)
    s = parse_spec("t=time_s")
    assert (s.scale, s.offset) == (1.0, 0.0)
    s = parse_spec("tau=force*1e-3")
    assert s.scale == pytest.approx(1e-3) and s.offset == 0.0
    with pytest.raises(LogError, match="not a canonical column"):
        parse_spec("speed=omega")
    with pytest.raises(LogError, match="neither a number nor a unit"):
        parse_spec("omega=speed*furlongs")


def test_read_with_comments_mapping_and_units(tmp_path):
    t = np.arange(100) * 0.01
    rpm = 60 * np.sin(t)
    p = tmp_path / "rig.csv"
    p.write_text("# kind: free-speed-step\n# rig: bench 3\n"
                 "time_ms, volts ,speed_rpm\n"
                 + "".join(f"{1000 * a:.3f},{1.5},{b:.9g}\n" for a, b in zip(t, rpm, strict=True)))
    before = p.read_bytes()
    mfile = tmp_path / "rig.map"
    mfile.write_text("# my rig\nt=time_ms*ms\nomega=speed_rpm*rpm\n")
    log = read_log(p, parse_mapping(["v=volts"], mfile))
    assert log.meta == {"kind": "free-speed-step", "rig": "bench 3"}
    assert log.dt == pytest.approx(0.01)
    assert np.allclose(log["omega"], 2 * np.pi * np.sin(t), atol=1e-8)
    assert log.drive == "v" and np.all(log.u == 1.5)
    assert p.read_bytes() == before  # never modified
    json_map = tmp_path / "rig.json"
    json_map.write_text(json.dumps({"t": "time_ms*ms", "omega": "speed_rpm*rpm", "v": "volts"}))
    log2 = read_log(p, parse_mapping([], json_map))
    assert np.array_equal(log2["omega"], log["omega"])


def test_few_nans_filled_with_warning(tmp_path):
    t = np.arange(500) * 1e-3
    x = np.sin(t)
    x[[10, 200, 201]] = np.nan
    p = tmp_path / "a.csv"
    write_log(p, t, {"v": np.ones_like(t), "omega": x})
    with pytest.warns(UserWarning, match="filled 3 NaN"):
        log = read_log(p)
    assert np.allclose(log["omega"][200], np.sin(0.2), atol=1e-5)


def test_small_jitter_accepted_large_resampled(tmp_path, rng):
    t = np.arange(1000) * 1e-3
    p = tmp_path / "j.csv"
    write_log(p, t + rng.uniform(-5e-6, 5e-6, t.size), {"v": np.ones_like(t)})
    log = read_log(p)
    assert log.dt == pytest.approx(1e-3, rel=1e-4) and log.resampled is None
    write_log(p, t + rng.uniform(-2e-4, 2e-4, t.size), {"v": np.ones_like(t)})
    with pytest.warns(UserWarning, match=r"loop-timed samples .* uniform 1(\.0\d)? ms grid"):
        log = read_log(p)
    assert log.resampled is not None and np.allclose(log["v"], 1.0)


def test_model_file_roundtrip_and_atomic_update(tmp_path):
    path = tmp_path / "m.json"
    assert load_model(path, must_exist=False).parameters == {}
    m = Model()
    m.set("R", 2.37, 0.004, stage="fit-electrical")
    m.set("fs", 1e-3, stage="diagnose")
    m.effects = ["stribeck"]
    save_model(m, path)
    obj = json.loads(path.read_text())
    assert obj["parameters"]["R"] == {"value": 2.37, "stderr": 0.004, "unit": "ohm",
                                      "stage": "fit-electrical"}
    assert obj["effects"] == ["stribeck"]
    back = load_model(path)
    assert back.value("R") == 2.37 and back.parameters["fs"].unit == "N m"
    assert not list(tmp_path.glob(".*tmp"))  # no temporary left behind


def test_model_rejects_impossible_values(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text(json.dumps({"parameters": {"R": {"value": -1.0}}}))
    with pytest.raises(ModelError, match="impossible"):
        load_model(p)
    p.write_text(json.dumps({"parameters": {}, "effects": ["warp_drive"]}))
    with pytest.raises(ModelError, match="unknown effect"):
        load_model(p)


def test_a_set_point_is_mapped_in_its_unit_and_kept_beside_the_signals(tmp_path):
    """``-c omega_ref=target_rpm*rpm``: the controller's set-point in rad/s, in ``Log.extra``
    (not a signal the model simulates); any other name is still refused, naming both lists."""
    t = np.arange(200) * 1e-3
    f = tmp_path / "loop.csv"
    write_log(f, t, {"v": np.ones(200), "omega": np.zeros(200), "target_rpm": np.full(200, 60.0)})
    log = read_log(f, parse_mapping(["omega_ref=target_rpm*rpm"]))
    assert "omega_ref" not in log.data
    assert np.allclose(log.extra["omega_ref"], 2 * math.pi)
    with pytest.raises(LogError, match="or a set-point"):
        parse_mapping(["speed_ref=target_rpm"])


@pytest.mark.parametrize("name, said", [
    ("omega_ref", True), ("targetSpeed", True), ("speed_sp", True), ("Setpoint", True),
    ("w_ref_rads", True), ("desired_rpm", True), ("motor_speed", False), ("voltage", False),
    ("spin", False), ("preference", False), ("temperature", False), ("duty", False),
])
def test_set_point_columns_are_known_by_their_names(name, said):
    assert is_setpoint(name) is said


def test_a_column_mapped_twice_is_refused_naming_both(tmp_path):
    with pytest.raises(LogError, match=r"omega is mapped twice, by -c omega=speed_rpm\*rpm and "
                                       r"by -c omega=speed_rpm: keep one"):
        parse_mapping(["omega=speed_rpm*rpm", "omega=speed_rpm"])
    assert parse_mapping(["omega=w", "omega = w*1"]).specs["omega"].source == "w"  # the same
    rig = tmp_path / "rig.map"
    rig.write_text("omega=speed_rpm*rpm\nt=time_ms*ms\nomega=speed\n")
    with pytest.raises(LogError, match=r"rig\.map: omega is mapped twice, by rig\.map line 1 "
                                       r"\(omega=speed_rpm\*rpm\) and by rig\.map line 3"):
        parse_mapping([], rig)
    rig_json = tmp_path / "rig.json"
    rig_json.write_text('{"omega": "speed_rpm*rpm", "omega": "speed"}')
    with pytest.raises(LogError, match=r"rig\.json entry 1 .* rig\.json entry 2"):
        parse_mapping([], rig_json)
    rig.write_text("omega=speed_rpm*rpm\n")  # a -c overriding the file is not a conflict
    assert parse_mapping(["omega=speed"], rig).specs["omega"].source == "speed"


def test_a_leading_minus_negates_the_source(tmp_path):
    s = parse_spec("omega=-speed_rpm*rpm+1")
    assert (s.source, s.offset) == ("speed_rpm", 1.0)
    assert s.scale == pytest.approx(-2 * math.pi / 60)
    p = tmp_path / "rig.csv"
    write_log(p, np.arange(50) * 1e-3, {"v": np.ones(50), "speed_rpm": np.full(50, 60.0)})
    log = read_log(p, parse_mapping(["omega=-speed_rpm*rpm"]))
    assert log["omega"][10] == pytest.approx(-2 * math.pi)
