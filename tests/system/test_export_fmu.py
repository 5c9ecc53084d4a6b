"""`pmdcid export --to fmu`: an FMI 2.0 co-simulation FMU that fmpy validates and that, driven by
a log's input at communication step = the log's sample period, steps as `pmdcid simulate` (the
assert: 1e-6 of each signal's standard deviation; measured 1e-13 at worst, the late input's
rounding, else 1e-16). Skipped without fmpy or a C compiler, saying which."""

import shutil
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest
from click.testing import CliRunner
from export_util import (
    LATER_EXTRA,
    dt_of,
    inputs,
    real_input,
    reference,
    rig_model,
    write_model,
)

from pmdcid.cli import main
from pmdcid.export import fmu
from pmdcid.synth import PAPER

fmpy = pytest.importorskip("fmpy", reason="fmpy not installed (pip install 'pmdcid[fmu]')")
pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler (cc/gcc) to build the FMU's binary")

KINDS = [("v", False, ()), ("tau", False, ()), ("lumped", False, ()),
         ("v", True, ("friction_curve", "input_delay")), ("v", True, ("lugre",)),
         ("tau", False, ("lugre", "input_delay")), ("instant", True, ())]
TOL = 1e-6


def export(tmp_path, name="motor.fmu", model="m.json"):
    res = CliRunner().invoke(main, ["export", "-m", str(tmp_path / model), "--to", "fmu",
                                    "-o", str(tmp_path / name)])
    assert res.exit_code == 0, res.output
    return tmp_path / name


def simulate_fmu(path, kind, t, u, **kw):
    """fmpy driving the FMU with the log's input, one communication step per sample."""
    from fmpy import simulate_fmu as run

    sig = np.array(list(zip(t, u, strict=True)),
                    dtype=[("time", float), ("tau" if kind == "tau" else "v", float)])
    res = run(str(path), start_time=t[0], stop_time=t[-1], step_size=dt_of(t),
              output_interval=dt_of(t), input=sig, output=["i", "omega", "theta"], **kw)
    assert len(res) == len(t)
    return np.column_stack([res["i"], res["omega"], res["theta"]])


def std_error(y, ref):
    """max |y - ref| / std(ref) per signal; a NaN reference (current not simulated) must be NaN."""
    out = []
    for k in range(ref.shape[1]):
        if np.isnan(ref[:, k]).all():
            assert np.isnan(y[:, k]).all()
            continue
        out.append(float(np.max(np.abs(y[:, k] - ref[:, k])) / np.std(ref[:, k])))
    return out


@pytest.mark.parametrize("kind,every,later", KINDS)
def test_validates_and_steps_as_simulate(tmp_path, kind, every, later):
    from fmpy.validation import validate_fmu

    model = write_model(tmp_path / "m.json", kind, every, later)
    path = export(tmp_path)
    assert validate_fmu(str(path)) == []
    for name, t, u in inputs(kind):
        err = std_error(simulate_fmu(path, kind, t, u), reference(t, u, model, kind))
        assert max(err) < TOL, (name, err)


def test_steps_as_simulate_on_a_measured_logs_voltage(tmp_path):
    """The FRA233 rig's +-12 V sine (30 s at 1 kHz, the log's own time stamps) through a model
    of that rig's size with a back-EMF: the FMU and simulate agree (measured 2e-14)."""
    t, u = real_input()
    model = rig_model(tmp_path / "m.json")
    err = std_error(simulate_fmu(export(tmp_path), "v", t, u), reference(t, u, model, "v"))
    print("measured log, max |FMU - simulate| / std (i, omega, theta)", err)
    assert max(err) < TOL, err


def test_parameters_are_fmu_parameters(tmp_path):
    """J and bc set through fmpy's start values change the motor as they change simulate's."""
    model = write_model(tmp_path / "m.json", "v")
    path = export(tmp_path)
    changed = model.copy()
    changed.parameters["J"].value *= 2.0
    changed.parameters["bc"].value *= 0.5
    name, t, u = inputs("v")[1]
    y = simulate_fmu(path, "v", t, u, start_values={"J": 2.0 * PAPER["J"],
                                                     "bc": 0.5 * PAPER["bc"]})
    assert max(std_error(y, reference(t, u, changed, "v"))) < TOL
    assert max(std_error(y, reference(t, u, model, "v"))) > 1e-2  # it did change


def test_contents(tmp_path):
    write_model(tmp_path / "m.json", "v", True, ("input_delay",))
    path = export(tmp_path, name="my motor.fmu")
    with zipfile.ZipFile(path) as zf:
        names = zf.namelist()
        desc = ET.fromstring(zf.read("modelDescription.xml"))
        wrapper = zf.read("sources/fmi2.c").decode()
    folder, suffix = fmu.platform_folder()
    assert names[0] == "modelDescription.xml"
    assert f"binaries/{folder}/my_motor{suffix}" in names
    for src in ("fmi2.c", "pmdc_model.c", "pmdc_model.h", "FMI2_LICENSE.txt", *fmu.HEADERS):
        assert "sources/" + src in names
    assert "pmdc_step" in wrapper
    cs = desc.find("CoSimulation")
    assert cs.get("modelIdentifier") == "my_motor"
    var = {v.get("name"): v for v in desc.iter("ScalarVariable")}
    assert var["v"].get("causality") == "input"
    assert [n for n, v in var.items() if v.get("causality") == "output"] == ["i", "omega", "theta"]
    assert float(var["latency"].find("Real").get("start")) == LATER_EXTRA["input_delay"]["latency"]
    assert float(var["R"].find("Real").get("start")) == PAPER["R"]
    assert var["vmax"].get("causality") == "parameter"


def test_sources_compile_cleanly(tmp_path):
    """sources/ builds on its own, warnings as errors (C99, pedantic): the FMU can be rebuilt."""
    import subprocess

    write_model(tmp_path / "m.json", "v", True, ("lugre",))
    with zipfile.ZipFile(export(tmp_path)) as zf:
        zf.extractall(tmp_path / "fmu")
    cc = shutil.which("gcc") or shutil.which("cc")
    subprocess.run([cc, "-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", "-shared",
                    "-fPIC", "-o", "m.so", "fmi2.c", "pmdc_model.c", "-lm"],
                   cwd=tmp_path / "fmu" / "sources", check=True)


def test_torque_model_has_no_electrical_parameters(tmp_path):
    write_model(tmp_path / "m.json", "tau")
    with zipfile.ZipFile(export(tmp_path)) as zf:
        desc = ET.fromstring(zf.read("modelDescription.xml"))
    names = {v.get("name") for v in desc.iter("ScalarVariable")}
    assert "tau" in names and not names & set(fmu.ELECTRICAL)


def test_missing_compiler_is_one_line(tmp_path, monkeypatch):
    write_model(tmp_path / "m.json", "v")
    monkeypatch.setenv("PATH", str(tmp_path / "nowhere"))
    monkeypatch.delenv("CC", raising=False)
    res = CliRunner().invoke(main, ["export", "-m", str(tmp_path / "m.json"), "--to", "fmu",
                                    "-o", str(tmp_path / "motor.fmu")])
    assert res.exit_code == 1
    assert "no C compiler found" in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not (tmp_path / "motor.fmu").exists()


def test_overwrites_its_own_fmu_only(tmp_path):
    write_model(tmp_path / "m.json", "v")
    path = export(tmp_path)
    export(tmp_path)  # again: its own file
    (tmp_path / "other.fmu").write_bytes(b"PK\x03\x04 someone else's archive")
    res = CliRunner().invoke(main, ["export", "-m", str(tmp_path / "m.json"), "--to", "fmu",
                                    "-o", str(tmp_path / "other.fmu")])
    assert res.exit_code == 1 and "--force" in res.output
    assert (tmp_path / "other.fmu").read_bytes().startswith(b"PK\x03\x04 someone")
    assert zipfile.is_zipfile(path)


def test_names_are_escaped(tmp_path):
    """A model file name with quotes, markup, comment closers and template marks reaches the
    modelDescription, the C comments and the identifier safely."""
    from fmpy.validation import validate_fmu

    write_model(tmp_path / 'a"b<c>&--*@@d.json', "v")
    path = export(tmp_path, name="9 lives.fmu", model='a"b<c>&--*@@d.json')
    assert validate_fmu(str(path)) == []
    with zipfile.ZipFile(path) as zf:
        desc = ET.fromstring(zf.read("modelDescription.xml"))
    assert desc.find("CoSimulation").get("modelIdentifier") == "pmdc_9_lives"


def test_c_string_and_comment_escapes():
    assert fmu.c_string('a"b\\c\n?é') == '"a\\"b\\\\c\\012\\077\\303\\251"'
    assert fmu.c_comment("x*/y/*z@@w\né") == "x* /y/ *z@ @w??"


def test_reset_starts_again_and_parameters_are_fixed_after_initialisation(tmp_path):
    """fmi2Reset brings the FMU back to rest with the exported parameters; a parameter set in
    step mode is refused (variability fixed)."""
    from fmpy import extract, read_model_description
    from fmpy.fmi1 import FMICallException
    from fmpy.fmi2 import FMU2Slave

    write_model(tmp_path / "m.json", "v")
    path = export(tmp_path)
    desc = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in desc.modelVariables}
    slave = FMU2Slave(guid=desc.guid, unzipDirectory=extract(str(path)),
                      modelIdentifier=desc.coSimulation.modelIdentifier, instanceName="m")
    slave.instantiate()

    def run():
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        slave.exitInitializationMode()
        out = []
        for k in range(200):
            slave.setReal([vr["v"]], [1.5])
            slave.doStep(k * 1e-3, 1e-3)
            out.append(slave.getReal([vr["i"], vr["omega"], vr["theta"]]))
        return np.array(out)

    first = run()
    with pytest.raises(FMICallException):
        slave.setReal([vr["J"]], [1.0])
    slave.reset()
    again = run()
    slave.terminate()
    slave.freeInstance()
    assert np.array_equal(first, again) and first[-1, 1] > 0.1
