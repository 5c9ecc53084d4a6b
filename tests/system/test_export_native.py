"""`pmdcid export --to c` and `--to matlab`: the generated code, compiled with the system's C
compiler (gcc -std=c99) or run by GNU Octave, steps the same model as the kernel (1e-9 relative).
Skipped, with the reason, when no compiler or no octave-cli is installed."""

import os
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner
from export_util import VOLTAGE_KINDS, dt_of, inputs, reference, rel_error, write_model
from repo_paths import REPO

from pmdcid.cli import main

CC = shutil.which("gcc") or shutil.which("cc")
OCTAVE = shutil.which("octave-cli")
#: (drive, every catalogue effect, effects ported later: friction curve and late input)
LATER = ("friction_curve", "input_delay")
#: the triangle's stretch the Octave checks step through [s] (export_util.inputs)
OCTAVE_WINDOW = (8.0, 22.0)
KINDS = [("v", False, ()), ("v", True, ()), ("tau", False, ()), ("lumped", False, ()),
         ("v", True, LATER), ("lumped", False, LATER), ("v", True, ("lugre",)),
         ("tau", False, ("lugre", "input_delay")), ("instant", True, ())]

DRIVER = r"""
#include <stdio.h>
#include "motor.h"
/* reads dt then the inputs; prints (i, omega + omega0, theta) before each step */
int main(void) {
    pmdc_params p; pmdc_model m; double dt, u;
    pmdc_default_params(&p);
    if (scanf("%lf", &dt) != 1 || pmdc_init(&m, &p, dt) != 0) return 1;
    while (scanf("%lf", &u) == 1) {
        printf("%.17g %.17g %.17g\n", m.i, pmdc_measured_omega(&m), m.theta);
        pmdc_step(&m, u);
    }
    return 0;
}
"""


def export(tmp_path, kind, every, fmt, name, later=()):
    model = write_model(tmp_path / "m.json", kind, every, later)
    res = CliRunner().invoke(main, ["export", "-m", str(tmp_path / "m.json"), "--to", fmt,
                                    "-o", str(tmp_path / name)])
    assert res.exit_code == 0, res.output
    return model


def compile_c(tmp_path, *sources, shared=False):
    exe = tmp_path / ("libmotor.so" if shared else "driver")
    flags = ["-shared", "-fPIC"] if shared else []
    subprocess.run([CC, "-std=c99", "-O2", "-Wall", "-Wextra", "-pedantic", "-Werror", *flags,
                    "-o", str(exe), *map(str, sources), "-lm"], check=True, cwd=tmp_path)
    return exe


@pytest.mark.skipif(CC is None, reason="no C compiler (gcc/cc) installed")
@pytest.mark.parametrize("kind,every,later", KINDS)
def test_c_matches_kernel(tmp_path, kind, every, later):
    model = export(tmp_path, kind, every, "c", "motor.c", later)
    assert (tmp_path / "motor.h").exists()
    (tmp_path / "driver.c").write_text(DRIVER)
    exe = compile_c(tmp_path, "driver.c", "motor.c")
    for name, t, u in inputs(kind):
        text = repr(dt_of(t)) + "\n" + "\n".join(repr(float(x)) for x in u) + "\n"
        out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
        y = np.loadtxt(out.stdout.splitlines())
        # the C state is the rotor's (no sensor delay): compare with the delay switched off
        undelayed = reference(t, u, _without_delay(model), kind)
        if kind not in VOLTAGE_KINDS:
            y[:, 0] = np.nan  # the current is not computed on the torque path
        err = rel_error(y, undelayed)
        assert max(err) < 1e-9, (name, err)


def _without_delay(model):
    m = model.copy()
    m.effects = [e for e in m.effects if e != "sensor_delay"]
    return m


@pytest.mark.skipif(CC is None, reason="no C compiler (gcc/cc) installed")
def test_c_input_line_bound(tmp_path):
    """pmdc_init refuses (-2) a latency needing more past inputs than PMDC_INPUT_LINE (256)
    at the dt given, and takes one that fits (the line lives in pmdc_model: no allocation)."""
    export(tmp_path, "v", False, "c", "motor.c", ("input_delay",))
    (tmp_path / "bound.c").write_text(r"""
#include <stdio.h>
#include "motor.h"
int main(void) {
    pmdc_params p; pmdc_model m; int rc;
    pmdc_default_params(&p);
    p.latency = 0.2555;
    rc = pmdc_init(&m, &p, 1e-3);
    printf("%d %d", rc, m.lag);
    p.latency = 0.2565;
    printf(" %d\n", pmdc_init(&m, &p, 1e-3));
    return 0;
}
""")
    out = subprocess.run([str(compile_c(tmp_path, "bound.c", "motor.c"))], capture_output=True,
                         text=True, check=True).stdout.split()
    assert out == ["0", "256", "-2"]


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave (octave-cli) not installed")
@pytest.mark.parametrize("kind,every,later,only", [  # Octave is slow: the two drive paths, all
    ("v", True, (), None), ("lumped", False, ("friction_curve",), None),  # terms, the curve's
    ("v", True, LATER, "step"), ("v", True, ("lugre",), None),  # knots on the triangle;
    ("instant", True, (), "step")])  # L = 0: the current follows the voltage at once
def test_matlab_matches_kernel_in_octave(tmp_path, kind, every, later, only):
    model = export(tmp_path, kind, every, "matlab", "motor.m", later)
    cases = [c for c in inputs(kind, OCTAVE_WINDOW) if only in (None, c[0])]
    code = []
    for k, (_, t, u) in enumerate(cases):
        np.savetxt(tmp_path / f"u{k}.txt", u, fmt="%.17g")
        code.append(f"u = load('u{k}.txt'); [i, w, th] = motor(u, {dt_of(t)!r}); "
                    f"fid = fopen('y{k}.txt', 'w'); fprintf(fid, '%.17g %.17g %.17g\\n', "
                    "[i w th]'); fclose(fid);")
    subprocess.run([OCTAVE, "--no-gui", "--norc", "--quiet", "--eval", " ".join(code)],
                   cwd=tmp_path, check=True, capture_output=True, env=dict(os.environ, DISPLAY=""))
    for k, (name, t, u) in enumerate(cases):
        y = np.loadtxt(tmp_path / f"y{k}.txt")
        err = rel_error(y, reference(t, u, model, kind))
        assert max(err) < 1e-9, (name, err)


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave (octave-cli) not installed")
def test_matlab_script_runs(tmp_path):
    export(tmp_path, "v", False, "matlab", "motor.m")
    out = subprocess.run([OCTAVE, "--no-gui", "--norc", "--quiet", "--eval", "run_motor"],
                         cwd=tmp_path, capture_output=True, text=True, check=True,
                         env=dict(os.environ, DISPLAY=""))
    assert "final: i =" in out.stdout


@pytest.mark.skipif(CC is None, reason="no C compiler (gcc/cc) installed")
def test_compensator_cuts_tracking_error_near_zero_speed(tmp_path):
    """docs/examples/compensator.py: a PD position loop on the paper's motor (the kernel) tracking
    a slow sinusoid through zero speed, with the exported C compensator called through ctypes."""
    import importlib.util

    path = REPO / "docs" / "examples" / "compensator.py"
    spec = importlib.util.spec_from_file_location("compensator_example", path)
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    without, with_, run0, run1 = example.demonstrate()
    # without it the rotor sticks at each reversal until the error drives the motor through
    # the dead zone (R dz / km = 0.30 V, i.e. 1.5 mrad at 200 V/rad)
    assert 1.0e-3 < without["max_slow"] < 2.5e-3
    assert without["max_slow"] >= 5 * with_["max_slow"]
    assert without["rms_slow"] >= 5 * with_["rms_slow"]
    assert with_["rms_moving"] < without["rms_moving"]  # no worse while moving
    example.figure(run0, run1, tmp_path / "c.png")
    assert (tmp_path / "c.png").stat().st_size < 100_000


@pytest.mark.skipif(CC is None, reason="no C compiler (gcc/cc) installed")
@pytest.mark.parametrize("kind", ["v", "lumped"])
def test_compensator_law(tmp_path, kind):
    """pmdc_compensate is the law in docs/export.md: u + g^-1 s (bc + fs exp(-(w/ws)^2)), then
    the dead zone jumped (nearest deliverable torque: 0 or at least dz); g = km/R or 1."""
    import ctypes

    model = export(tmp_path, kind, False, "c", "motor.c")
    lib = ctypes.CDLL(str(compile_c(tmp_path, "motor.c", shared=True)))
    params = (ctypes.c_double * 64)()  # room for pmdc_params (32 doubles)
    lib.pmdc_default_params(params)
    lib.pmdc_compensate.restype = ctypes.c_double
    lib.pmdc_compensate.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]

    def comp(u, w):
        return lib.pmdc_compensate(ctypes.addressof(params), u, w)

    v = {n: p.value for n, p in model.parameters.items()}
    g = v["km"] / v["R"] if kind == "v" else 1.0
    for u, w in [(1.0, 0.3), (-0.7, -2.0), (1.5, -0.1), (-2.0, 1.0)]:
        friction = v["bc"] + v["fs"] * np.exp(-(w / v["ws"]) ** 2)
        assert comp(u, w) == pytest.approx(u + np.sign(w) * friction / g, rel=1e-12)
    # near zero torque: nothing below dz/2, the dead zone's edge dz above it
    assert comp(0.0, 0.0) == 0.0
    assert comp(-(v["bc"] + v["fs"] * np.exp(-1.0)) / g, v["ws"]) == 0.0
    tiny = (0.5 * v["dz"] - v["bc"] - v["fs"]) / g + 1e-6
    assert comp(tiny, 1e-9) == pytest.approx(v["dz"] / g, rel=1e-12)
    assert comp(-tiny, -1e-9) == pytest.approx(-v["dz"] / g, rel=1e-12)
