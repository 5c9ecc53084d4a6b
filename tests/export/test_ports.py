"""`pmdcid export --to python-control`, and the command's errors (exit 1 one line, exit 2)."""

import importlib.util
import json

import numpy as np
import pytest
from click.testing import CliRunner
from export_util import dt_of, inputs, reference, rel_error, write_model

from pmdcid.cli import main
from pmdcid.export import drive_of
from pmdcid.model import Model

control = pytest.importorskip("control", reason="python-control (the 'export' extra) not installed")


def load_module(path):
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


#: the effects ported later (friction curve, late input), both on
LATER = ("friction_curve", "input_delay")


def export(tmp_path, kind, fmt="python-control", name="motor_model.py", every_effect=False,
           later=()):
    model = write_model(tmp_path / "m.json", kind, every_effect, later)
    out = tmp_path / name
    res = CliRunner().invoke(main, ["export", "-m", str(tmp_path / "m.json"), "--to", fmt,
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output
    return model, out


@pytest.mark.parametrize("kind,every,later", [
    ("v", False, ()), ("v", True, ()), ("tau", False, ()), ("lumped", False, ()),
    ("v", True, ("friction_curve",)), ("v", True, LATER), ("tau", False, LATER),
    ("v", True, ("lugre",)), ("lumped", False, ("lugre", "input_delay")), ("instant", True, ())])
def test_python_control_matches_simulate(tmp_path, kind, every, later):
    model, out = export(tmp_path, kind, every_effect=every, later=later)
    mod = load_module(out)
    for name, t, u in inputs(kind):
        sys = mod.make_system(dt_of(t))
        assert sys.isdtime() and sys.input_labels == ["tau" if kind == "tau" else "v"]
        assert sys.output_labels == ["i", "omega", "theta"]
        res = control.input_output_response(sys, t - t[0], u)
        ref = reference(t, u, model, kind)
        assert np.ptp(ref[:, 1]) > 0.1  # the rotor moves (and sticks at the triangle's reversal)
        err = rel_error(res.outputs.T, ref)
        assert max(err) < 1e-9, (name, err)


def test_python_control_delay_line_in_state(tmp_path):
    _, out = export(tmp_path, "v")
    sys = load_module(out).make_system(1e-3)
    # 2.5 ms at 1 ms: the speed and angle of the last 3 samples are states
    assert sys.nstates == 3 + 2 * 3


def test_python_control_late_input_line_in_state(tmp_path):
    """A latency of 2.6 ms at 1 ms needs the last 3 inputs (states u_d1..u_d3, then
    ``started``). From python-control's default all-zero state the first step takes the input
    before t0 to be the first one, as simulate does: a triangle starting at +12 V agrees (with
    u_d1.. 0 it differed by 0.13 rad/s); u_d1.. given with started = 1 are used as they are."""
    model, out = export(tmp_path, "v", later=("input_delay",))
    sys = load_module(out).make_system(1e-3)
    assert sys.state_labels[3:7] == ["u_d1", "u_d2", "u_d3", "started"]
    assert sys.nstates == 7 + 2 * 3
    t = np.arange(600) * 1e-3
    u = 12.0 * (4.0 * np.abs((t / 0.2) % 1.0 - 0.5) - 1.0)  # a triangle from +12 V
    ref = reference(t, u, model, "v")
    err = rel_error(control.input_output_response(sys, t, u).outputs.T, ref)
    assert max(err) < 1e-9, err
    x0 = np.zeros(sys.nstates)
    x0[3:7] = [u[0], u[0], u[0], 1.0]  # the line given, as a caller continuing a run would
    err = rel_error(control.input_output_response(sys, t, u, X0=x0).outputs.T, ref)
    assert max(err) < 1e-9, err


def test_python_control_bristle_state(tmp_path):
    """With LuGre the bristle deflection z is the fourth state, as the kernel's z."""
    from pmdcid.simulate import param_values, param_vector, run_kernel
    from pmdcid.simulate.layout import Z_STATE

    model, out = export(tmp_path, "tau", later=("lugre",))
    _, t, u = inputs("tau")[0]
    sys = load_module(out).make_system(dt_of(t))
    assert sys.state_labels[:4] == ["i", "omega", "theta", "z"]
    z = control.input_output_response(sys, t - t[0], u, return_x=True).states[3]
    ref = run_kernel(u, dt_of(t), param_vector(param_values(model, True)), True)[:, Z_STATE]
    assert np.max(np.abs(ref)) > 1e-3  # deflected to (bc + fs) / sigma0 = 1.6 mrad
    assert np.max(np.abs(z - ref)) < 1e-9 * np.max(np.abs(ref))


def test_drive_of():
    assert drive_of(Model(extra={"lumped": True})) == "lumped"
    m = Model()
    m.set("J", 1e-3)
    assert drive_of(m) == "tau"
    for n in ("R", "L", "km"):
        m.set(n, 1.0)
    assert drive_of(m) == "v"


def run(args):
    return CliRunner().invoke(main, ["export"] + args)


def one_line_error(res):
    assert res.exit_code == 1, res.output
    lines = res.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in res.output
    return lines[0]


def test_effect_the_shells_do_not_carry_is_refused(tmp_path, monkeypatch):
    """Every kernel parameter is stepped (the physics is generated from the kernel's source);
    a sensor parameter or an effect state the templates' shells do not carry (played here by
    sensor_delay's delay and LuGre's z) leaves its effect refused in one line, not exported
    without it."""
    import pmdcid.export as ex

    write_model(tmp_path / "m.json", "v", later=("lugre",))
    monkeypatch.setattr(ex, "PORTED_STATES", ())
    msg = one_line_error(run(["-m", str(tmp_path / "m.json"), "--to", "c",
                              "-o", str(tmp_path / "x.c")]))
    assert "lugre" in msg and "sensor_delay" not in msg and not (tmp_path / "x.c").exists()
    monkeypatch.setattr(ex, "PORTED_SENSORS", ("omega0",))
    assert "sensor_delay" in one_line_error(run(["-m", str(tmp_path / "m.json"), "--to",
                                                 "matlab", "-o", str(tmp_path / "x.m")]))
    monkeypatch.undo()
    assert run(["-m", str(tmp_path / "m.json"), "--to", "python-control",
                "-o", str(tmp_path / "x.py")]).exit_code == 0


def test_unknown_format_is_a_usage_error(tmp_path):
    write_model(tmp_path / "m.json")
    res = run(["-m", str(tmp_path / "m.json"), "--to", "fortran", "-o", str(tmp_path / "x")])
    assert res.exit_code == 2 and "fortran" in res.output


def test_model_lacking_parameters(tmp_path):
    (tmp_path / "m.json").write_text(json.dumps({"parameters": {"R": 2.0, "L": 0.01}}))
    msg = one_line_error(run(["-m", str(tmp_path / "m.json"), "--to", "c",
                              "-o", str(tmp_path / "x.c")]))
    assert "km" in msg
    (tmp_path / "m.json").write_text(json.dumps({"parameters": {"bc": 0.1}}))
    assert "J" in one_line_error(run(["-m", str(tmp_path / "m.json"), "--to", "python-control",
                                      "-o", str(tmp_path / "x.py")]))
    assert not (tmp_path / "x.py").exists() and not (tmp_path / "x.c").exists()


@pytest.mark.parametrize("fmt,name,other", [("python-control", "out.py", None),
                                            ("c", "out.c", "out.h"),
                                            ("matlab", "out.m", "run_out.m"),
                                            ("mujoco", "out.xml", None)])
def test_does_not_overwrite_foreign_files(tmp_path, fmt, name, other):
    write_model(tmp_path / "model.json")
    for victim in [name] + ([other] if other else []):
        for f in tmp_path.glob("*out*"):
            f.unlink()
        (tmp_path / victim).write_text("t,v\n0,1\n")  # e.g. a log
        args = ["-m", str(tmp_path / "model.json"), "--to", fmt, "-o", str(tmp_path / name)]
        assert "--force" in one_line_error(run(args))
        assert (tmp_path / victim).read_text() == "t,v\n0,1\n"
        assert run(args + ["--force"]).exit_code == 0
        assert run(args).exit_code == 0  # what it wrote itself it may overwrite
    model_bytes = (tmp_path / "model.json").read_bytes()
    msg = one_line_error(run(["-m", str(tmp_path / "model.json"), "--to", fmt, "-o",
                              str(tmp_path / "model.json"), "--force"]))
    assert "model" in msg and (tmp_path / "model.json").read_bytes() == model_bytes


def test_bad_output_names(tmp_path):
    write_model(tmp_path / "m.json")
    m = str(tmp_path / "m.json")
    assert "NAME.m" in one_line_error(run(["-m", m, "--to", "matlab", "-o",
                                           str(tmp_path / "2motor.m")]))
    assert "source" in one_line_error(run(["-m", m, "--to", "c", "-o", str(tmp_path / "x.h")]))
    assert "folder" in one_line_error(run(["-m", m, "--to", "c", "-o",
                                           str(tmp_path / "no" / "x.c")]))


def test_cli_formats_are_the_library_formats():
    from pmdcid.cli import cmd_export
    from pmdcid.export import FORMATS

    assert cmd_export.FORMATS == FORMATS
