"""`pmdcid export --to c` and `--to matlab`: the generated code, compiled with the system's C
compiler (gcc -std=c99) or run by GNU Octave, steps the same model as the kernel (1e-9 relative).
Skipped, with the reason, when no compiler or no octave-cli is installed."""

import os
import shutil
import subprocess

import numpy as np
import pytest
from click.testing import CliRunner
from export_util import dt_of, inputs, reference, rel_error, write_model

from pmdcid.cli import main

CC = shutil.which("gcc") or shutil.which("cc")
OCTAVE = shutil.which("octave-cli")
KINDS = [("v", False), ("v", True), ("tau", False), ("lumped", False)]

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


def export(tmp_path, kind, every, fmt, name):
    model = write_model(tmp_path / "m.json", kind, every)
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
@pytest.mark.parametrize("kind,every", KINDS)
def test_c_matches_kernel(tmp_path, kind, every):
    model = export(tmp_path, kind, every, "c", "motor.c")
    assert (tmp_path / "motor.h").exists()
    (tmp_path / "driver.c").write_text(DRIVER)
    exe = compile_c(tmp_path, "driver.c", "motor.c")
    for name, t, u in inputs(kind):
        text = repr(dt_of(t)) + "\n" + "\n".join(repr(float(x)) for x in u) + "\n"
        out = subprocess.run([str(exe)], input=text, capture_output=True, text=True, check=True)
        y = np.loadtxt(out.stdout.splitlines())
        # the C state is the rotor's (no sensor delay): compare with the delay switched off
        undelayed = reference(t, u, _without_delay(model), kind)
        if kind != "v":
            y[:, 0] = np.nan  # the current is not computed on the torque path
        err = rel_error(y, undelayed)
        assert max(err) < 1e-9, (name, err)


def _without_delay(model):
    m = model.copy()
    m.effects = [e for e in m.effects if e != "sensor_delay"]
    return m


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave (octave-cli) not installed")
@pytest.mark.parametrize("kind,every", KINDS)
def test_matlab_matches_kernel_in_octave(tmp_path, kind, every):
    model = export(tmp_path, kind, every, "matlab", "motor.m")
    for name, t, u in inputs(kind):
        np.savetxt(tmp_path / "u.txt", u, fmt="%.17g")
        code = (f"u = load('u.txt'); [i, w, th] = motor(u, {dt_of(t)!r}); "
                "fid = fopen('y.txt', 'w'); fprintf(fid, '%.17g %.17g %.17g\\n', [i w th]'); "
                "fclose(fid);")
        subprocess.run([OCTAVE, "--no-gui", "--norc", "--quiet", "--eval", code], cwd=tmp_path,
                       check=True, capture_output=True, env=dict(os.environ, DISPLAY=""))
        y = np.loadtxt(tmp_path / "y.txt")
        err = rel_error(y, reference(t, u, model, kind))
        assert max(err) < 1e-9, (name, err)


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave (octave-cli) not installed")
def test_matlab_script_runs(tmp_path):
    export(tmp_path, "v", False, "matlab", "motor.m")
    out = subprocess.run([OCTAVE, "--no-gui", "--norc", "--quiet", "--eval", "run_motor"],
                         cwd=tmp_path, capture_output=True, text=True, check=True,
                         env=dict(os.environ, DISPLAY=""))
    assert "final: i =" in out.stdout
