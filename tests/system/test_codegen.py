"""The exported forms are the kernel: C (gcc via ctypes), MATLAB (GNU Octave) and python-control,
each generated from the kernel's source (pmdcid/export/codegen.py), give what ``pmdcid simulate``
gives on random motors from ``numpy.random.default_rng(seed)`` whose effects cover every branch
of the kernel: stick-slip (sticking, breakaway, stops), the dead zone (slope and jump), Coulomb,
viscous and its asymmetry, Stribeck, quadratic drag (negative: the positivity hold acts), the
friction curve, LuGre, load torque and cogging, the brush drop, voltage saturation, the late
input, the torque path and the lumped model, and the sensors as each form applies them.

Tolerance: 1e-12 of each signal's largest magnitude (measured: C and Octave agree to the bit,
python-control to the bit but for its sensor delay line, 1e-15); with a late input 1e-9 (the
kernel builds the late input from the input's running integral, whose rounding reaches 1e-11 of
the input after 3000 samples; the exports weigh the samples directly). The kernel's own check
against the continuous-time model is tests/simulate/test_kernel.py.
"""

import ctypes
import math
import os
import shutil
import subprocess

import numpy as np
import pytest

from pmdcid.export import export_model
from pmdcid.export.codegen import CodegenError, c_kernel, collect, matlab_kernel, python_kernel
from pmdcid.model import save_model
from pmdcid.simulate import simulate
from pmdcid.synth import PAPER, triangle, truth_model

CC = shutil.which("gcc") or shutil.which("cc")
OCTAVE = shutil.which("octave-cli") or shutil.which("octave")
TOL = 1e-12
LATE_TOL = 1e-9
DT = 1e-3
#: (drive, effects, twist): together every branch of the kernel; the twists reach the rare
#: ones: an electrical time constant far below the step (the exponential's squaring), two
#: friction-curve knots at one speed (a jump), LuGre without a Coulomb level (infinite rate)
CASES = [
    ("v", ("back_emf", "stribeck", "quadratic_drag", "torque_offset", "cogging",
           "voltage_saturation", "brush_drop", "viscous_asymmetry", "sensor_delay",
           "speed_offset"), None),
    ("v", ("back_emf", "friction_curve", "input_delay", "speed_offset"), "fast electrical"),
    ("v", ("back_emf", "lugre", "stribeck", "cogging", "brush_drop", "voltage_saturation"), None),
    ("tau", ("stribeck", "cogging", "friction_curve", "quadratic_drag", "sensor_delay"),
     "tied knots"),
    ("tau", ("lugre", "input_delay", "torque_offset", "viscous_asymmetry"), None),
    ("tau", ("lugre",), "no Coulomb"),
    ("lumped", ("stribeck", "speed_offset"), None),
]


def random_values(rng, drive, effects, twist=None) -> dict[str, float]:
    """The paper's motor with each parameter scaled at random, and random effect values of the
    size that makes each act on :func:`random_input` (the saturation below its peak, knots at
    the speeds it reaches, a late input of 0.3-3 samples, 0.5-2 mrad of presliding)."""
    def scaled(x):
        return x * float(np.exp(0.3 * rng.standard_normal()))

    vals = {k: scaled(v) for k, v in PAPER.items()}
    bc, bv, J = vals["bc"], vals["bv"], vals["J"]
    vals.update(dz_slope=float(rng.uniform(0.8, 1.2)), dz_offset=float(rng.uniform(0, 1e-3)))
    knots = np.sort(rng.uniform(0.05, 1.2, 4))
    if twist == "tied knots":
        knots[1] = knots[0]
    if twist == "fast electrical":
        vals["L"] *= 0.01  # R/L h ~ 13: the exponential is scaled and squared back
    if twist == "no Coulomb":
        vals["bc"] = 0.0
    sigma0 = bc / (1e-3 * float(rng.uniform(0.5, 2.0)))
    extra = {
        "ke": scaled(vals["km"]), "fs": bc * rng.uniform(0.2, 1.0), "ws": rng.uniform(0.2, 1.0),
        "bq": -rng.uniform(0.02, 0.05) if drive == "tau" else rng.uniform(-1e-3, 1e-3),
        "tau0": bc * rng.uniform(-0.3, 0.3), "ca": bc * rng.uniform(0.1, 0.5),
        "cn": float(rng.integers(4, 12)), "cphi": rng.uniform(0, 2 * math.pi),
        "vmax": rng.uniform(1.2, 1.8), "vb": rng.uniform(0.05, 0.2),
        "dbv": bv * rng.uniform(-0.3, 0.3), "latency": DT * rng.uniform(0.3, 3.0),
        "sigma0": sigma0, "sigma1": 2 * math.sqrt(J * sigma0) * rng.uniform(0.1, 0.5),
        "delay": DT * rng.uniform(0.5, 3.0), "omega0": rng.uniform(-0.05, 0.05),
        **{f"fcw{k + 1}": knots[k] for k in range(4)},
        **{f"fc{k + 1}": bc * rng.uniform(-0.3, 0.5) for k in range(3)},
    }
    from pmdcid.model import EFFECTS

    for e in effects:
        vals.update({n: float(extra[n]) for n in EFFECTS[e].param_names})
    if drive != "v":
        for n in ("R", "L", "km"):
            vals.pop(n)
    return vals


def random_input(rng, drive, vals):
    """3 s at 1 kHz: a +-2 V triangle (through zero speed: sticking, breakaway, reversal) with
    noise, then rest; on the torque path the same scaled by the paper's km/R."""
    t = np.arange(3000) * DT
    u = triangle(t, 2.0, 2.0) + 0.02 * rng.standard_normal(len(t))
    u[t > 2.5] = 0.0
    if drive == "tau":
        u *= PAPER["km"] / PAPER["R"]
    return t, u


def cases(seed=25):
    rng = np.random.default_rng(seed)
    for drive, effects, twist in CASES:
        vals = random_values(rng, drive, effects, twist)
        model = truth_model(vals, effects)
        if drive == "lumped":
            model.extra["lumped"] = True
        yield drive, model, *random_input(rng, drive, vals)


def reference(model, t, u, drive, delayed=True):
    """(i, omega, theta) as ``pmdcid simulate`` gives them (i NaN on the torque path)."""
    if not delayed:
        model = model.copy()
        model.effects = [e for e in model.effects if e != "sensor_delay"]
    sim = simulate(t, u, model, torque_driven=drive != "v")
    assert np.ptp(sim.omega_true) > 0.1  # the rotor moves
    return np.column_stack([sim.i, sim.omega, sim.theta])


def assert_close(y, ref, what, model):
    tol = LATE_TOL if "input_delay" in model.effects else TOL
    for k, name in enumerate(("i", "omega", "theta")):
        if np.isnan(ref[:, k]).all():
            assert np.isnan(y[:, k]).all(), (what, name)
            continue
        err = np.max(np.abs(y[:, k] - ref[:, k])) / np.max(np.abs(ref[:, k]))
        assert err < tol, (what, name, err)


def export(tmp_path, model, fmt, name):
    save_model(model, tmp_path / f"{name}.json")
    return export_model(str(tmp_path / f"{name}.json"), fmt, str(tmp_path / name))


DRIVER = r"""
#include <string.h>
#include "motor.h"
/* the exported model's parameters, stepped over u: (i, omega as read, theta) per sample */
void run(double dt, const double *u, int n, double *out)
{
    pmdc_params p;
    pmdc_model m;
    int k;
    pmdc_default_params(&p);
    pmdc_init(&m, &p, dt);
    for (k = 0; k < n; k++) {
        out[3 * k] = PMDC_TORQUE_PATH ? 0.0 / 0.0 : m.i;
        out[3 * k + 1] = pmdc_measured_omega(&m);
        out[3 * k + 2] = m.theta;
        pmdc_step(&m, u[k]);
    }
}
"""


@pytest.mark.skipif(CC is None, reason="no C compiler (gcc/cc) installed")
def test_c_is_the_kernel(tmp_path):
    for k, (drive, model, t, u) in enumerate(cases()):
        folder = tmp_path / f"c{k}"
        folder.mkdir()
        export(folder, model, "c", "motor.c")
        (folder / "driver.c").write_text(DRIVER)
        lib = folder / "libmotor.so"
        subprocess.run([CC, "-std=c99", "-O2", "-ffp-contract=off", "-shared", "-fPIC", "-o",
                        str(lib), "driver.c", "motor.c", "-lm"], cwd=folder, check=True)
        run = ctypes.CDLL(str(lib)).run
        out = np.empty((len(u), 3))
        run.argtypes = [ctypes.c_double, ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p]
        run(DT, np.ascontiguousarray(u).ctypes.data, len(u), out.ctypes.data)
        # the C state is the rotor's: its speed sensor adds omega0 but does not delay
        assert_close(out, reference(model, t, u, drive, delayed=False), (k, drive), model)


@pytest.mark.skipif(OCTAVE is None, reason="GNU Octave not installed")
def test_matlab_is_the_kernel(tmp_path):
    code, refs = [], []
    for k, (drive, model, t, u) in enumerate(cases()):
        export(tmp_path, model, "matlab", f"motor{k}.m")
        np.savetxt(tmp_path / f"u{k}.txt", u, fmt="%.17g")
        code.append(f"u = load('u{k}.txt'); [i, w, th] = motor{k}(u, {DT!r}); "
                    f"fid = fopen('y{k}.txt', 'w'); fprintf(fid, '%.17g %.17g %.17g\\n', "
                    "[i w th]'); fclose(fid);")
        refs.append((drive, model, reference(model, t, u, drive)))
    subprocess.run([OCTAVE, "--no-gui", "--norc", "--quiet", "--eval", " ".join(code)],
                   cwd=tmp_path, check=True, capture_output=True, env=dict(os.environ, DISPLAY=""))
    for k, (drive, model, ref) in enumerate(refs):
        assert_close(np.loadtxt(tmp_path / f"y{k}.txt"), ref, (k, drive), model)


def test_python_control_is_the_kernel(tmp_path):
    control = pytest.importorskip("control", reason="python-control not installed")
    import importlib.util

    for k, (drive, model, t, u) in enumerate(cases()):
        path = export(tmp_path, model, "python-control", f"motor{k}.py")[0]
        spec = importlib.util.spec_from_file_location(f"motor{k}", path)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
        system = mod.make_system(DT)
        x0 = np.zeros(system.nstates)
        x0[[j for j, s in enumerate(system.state_labels) if s.startswith("u_d")]] = u[0]
        res = control.input_output_response(system, t, u, X0=x0)
        assert_close(res.outputs.T, reference(model, t, u, drive), (k, drive), model)


def test_every_form_holds_every_kernel_function():
    """The three forms carry the same functions: the entries and all they call."""
    names = [fn.name.lstrip("_") for fn in collect()]
    assert {"stick_substep", "lugre_substep", "discretize_into", "sliding_friction",
            "friction_curve", "bristle_step", "expm_small", "max_step"} <= set(names)
    c, m, py = c_kernel(), matlab_kernel(), python_kernel()
    for n in names:
        assert f" {n}(" in c and f" {n}(" in m, n
        assert f"def {n}(" in py or f"def _{n}(" in py, n
    assert "@njit" not in py and "range(30)" in py  # the layout's 30 slots, from layout.py


def test_code_outside_the_subset_is_refused():
    """A kernel edit the translator cannot write (here a list) fails the export loudly, naming
    the function."""
    def uses_a_list(p, v):
        return [v][0]

    with pytest.raises(CodegenError, match="uses_a_list"):
        collect((uses_a_list,))


def test_the_runtime_source_is_current():
    """pmdcid/simulate/_kernel.c is what the kernel's source generates today (after an edit:
    python -m pmdcid.export.codegen); the build compiles it."""
    from pmdcid.export.codegen import RUNTIME_SOURCE, runtime_source

    assert RUNTIME_SOURCE.read_text() == runtime_source(), "run: python -m pmdcid.export.codegen"
