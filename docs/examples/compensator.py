"""The exported C compensator in a PD position loop on the paper's motor (see compensator.md).

    python docs/examples/compensator.py OUTDIR [--model MODEL.json]

Exports MODEL (default: the paper's true parameters, fixtures/paper/truth.json) with
``pmdcid export --to c``, compiles it with the system's C compiler into a shared library and
calls its ``pmdc_compensate`` through ctypes. The plant is pmdcid's kernel with the true
parameters, stepped one control period at a time. A PD controller tracks a slow sinusoid
(1 rad, 40 s period: the speed goes through zero at 10 s and 30 s) with and without the compensator.
Prints the tracking errors and writes OUTDIR/compensator.png.
"""

from __future__ import annotations

import argparse
import ctypes
import json
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from pmdcid.export import export_model
from pmdcid.model import load_model
from pmdcid.simulate import param_values, param_vector, run_kernel

ROOT = Path(__file__).resolve().parents[2]
TRUTH = ROOT / "fixtures" / "paper" / "truth.json"
DT = 2e-3  # control period [s]
AMPLITUDE, PERIOD, SECONDS = 1.0, 40.0, 40.0  # reference [rad], [s], [s]: reversals at 10, 30 s
KP, KD, VMAX = 200.0, 5.0, 12.0  # PD gains [V/rad], [V s/rad] (damping ~0.6); drive limit [V]
SLOW = 0.1  # "near zero speed": |omega_ref| below this fraction of its peak


def compensator(model_path: str | Path, workdir: Path):
    """(compensate(u_ctrl, omega_ref) -> u, library) from the model exported to C and compiled."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("needs a C compiler (cc or gcc)")
    export_model(str(model_path), "c", str(workdir / "motor.c"), force=True)
    lib_path = workdir / "libmotor.so"
    subprocess.run([cc, "-std=c99", "-O2", "-shared", "-fPIC", "-o", str(lib_path),
                    str(workdir / "motor.c"), "-lm"], check=True)
    lib = ctypes.CDLL(str(lib_path))
    params = (ctypes.c_double * 64)()  # room for pmdc_params (32 doubles)
    lib.pmdc_default_params(params)
    lib.pmdc_compensate.restype = ctypes.c_double
    lib.pmdc_compensate.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double]
    return (lambda u, w: lib.pmdc_compensate(ctypes.addressof(params), u, w)), lib


def closed_loop(plant: np.ndarray, compensate=None) -> dict[str, np.ndarray]:
    """PD position loop on the kernel ``plant`` (parameter vector), optionally compensated."""
    t = np.arange(int(round(SECONDS / DT)) + 1) * DT
    w0 = 2 * np.pi / PERIOD
    th_ref, w_ref = AMPLITUDE * np.sin(w0 * t), AMPLITUDE * w0 * np.cos(w0 * t)
    x = np.zeros(3)
    theta, v = np.zeros(len(t)), np.zeros(len(t))
    for k in range(len(t)):
        theta[k] = x[2]
        u = KP * (th_ref[k] - x[2]) + KD * (w_ref[k] - x[1])
        if compensate is not None:
            u = compensate(u, w_ref[k])
        v[k] = min(max(u, -VMAX), VMAX)
        x = run_kernel(np.array([v[k], 0.0]), DT, plant, False, None, x)[1]
    return {"t": t, "theta_ref": th_ref, "omega_ref": w_ref, "theta": theta, "v": v}


def errors(run: dict[str, np.ndarray]) -> dict[str, float]:
    """Tracking error [rad]: max and RMS near zero speed, RMS elsewhere."""
    e = run["theta_ref"] - run["theta"]
    slow = np.abs(run["omega_ref"]) < SLOW * np.max(np.abs(run["omega_ref"]))
    return {"max_slow": float(np.max(np.abs(e[slow]))),
            "rms_slow": float(np.sqrt(np.mean(e[slow] ** 2))),
            "rms_moving": float(np.sqrt(np.mean(e[~slow] ** 2)))}


def demonstrate(model_path: str | Path = TRUTH) -> tuple[dict, dict, dict, dict]:
    """(errors without, errors with, run without, run with) on the paper's true motor."""
    plant = param_vector(param_values(load_model(TRUTH)))
    with tempfile.TemporaryDirectory() as tmp:
        comp, _lib = compensator(model_path, Path(tmp))
        without, with_ = closed_loop(plant), closed_loop(plant, comp)
    return errors(without), errors(with_), without, with_


def figure(without, with_, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(2, 1, figsize=(7, 4.2), sharex=True)
    for run, label in ((without, "PD"), (with_, "PD + compensator")):
        ax[0].plot(run["t"], 1e3 * (run["theta_ref"] - run["theta"]), lw=0.8, label=label)
        ax[1].plot(run["t"], run["v"], lw=0.8, label=label)
    slow = np.abs(without["omega_ref"]) < SLOW * np.max(np.abs(without["omega_ref"]))
    for a in ax:
        a.fill_between(without["t"], 0, 1, where=slow, color="0.9",
                       transform=a.get_xaxis_transform())
    ax[0].set_ylabel("error [mrad]")
    ax[1].set_ylabel("v [V]")
    ax[1].set_xlabel("t [s] (grey: |omega_ref| < 10 % of its peak)")
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=70)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--model", default=str(TRUTH), help="model whose compensator is exported")
    args = ap.parse_args(argv)
    args.outdir.mkdir(parents=True, exist_ok=True)
    e0, e1, r0, r1 = demonstrate(args.model)
    figure(r0, r1, args.outdir / "compensator.png")
    print(json.dumps({"without": e0, "with": e1,
                      "ratio_max_slow": e0["max_slow"] / e1["max_slow"],
                      "ratio_rms_slow": e0["rms_slow"] / e1["rms_slow"]}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
