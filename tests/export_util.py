"""Shared by the export tests: models with effects on, inputs from the fixtures, the reference."""


import numpy as np
from repo_paths import FIXTURES

from pmdcid.io import read_log
from pmdcid.model import save_model
from pmdcid.simulate import simulate
from pmdcid.synth import PAPER, truth_model

FIX = FIXTURES / "paper"

#: paper's motor with back-EMF, Stribeck and both sensor effects (delay of 2.5 samples at 1 ms)
EFFECTS = ["back_emf", "stribeck", "sensor_delay", "speed_offset"]
EXTRA = {"ke": 0.0502, "fs": 0.003, "ws": 0.5, "delay": 0.0025, "omega0": 0.01}
#: every other catalogue effect on as well
ALL_EFFECTS = EFFECTS + ["quadratic_drag", "torque_offset", "cogging", "voltage_saturation",
                         "brush_drop", "viscous_asymmetry"]
ALL_EXTRA = dict(EXTRA, bq=2e-4, tau0=5e-4, ca=1e-3, cn=6.0, cphi=0.3, vmax=1.8, vb=0.1,
                 dbv=3e-3)

#: effects the exporters gained later, and values that exercise them on :func:`inputs`: curve
#: knots the triangle's speeds (up to ~1.1 rad/s) and the step's (~0.7 rad/s) pass; a latency
#: that is no multiple of the sample period nor of the late input's fine grid (dt/8); LuGre's
#: bristles (the paper's bc over 1 mrad, presliding damping ratio 0.3)
LATER_EXTRA = {"friction_curve": {"fcw1": 0.1, "fcw2": 0.3, "fcw3": 0.6, "fcw4": 1.0,
                                  "fc1": 0.002, "fc2": 0.003, "fc3": 0.0015},
               "input_delay": {"latency": 2.6e-3},
               "lugre": {"sigma0": 5.0, "sigma1": 0.075}}  # 1 mrad presliding at bc


#: the kinds driven by a voltage: 'instant' is 'v' with L = 0 (the current follows the voltage)
VOLTAGE_KINDS = ("v", "instant")


def write_model(path, kind="v", every_effect=False, later=()):
    """A model file: 'v' (voltage), 'instant' (voltage, L = 0), 'tau' (no R, L, km) or 'lumped'
    (per-volt, lumped: true); ``later``: effects of :data:`LATER_EXTRA` to switch on as well."""
    vals = dict(PAPER, **(ALL_EXTRA if every_effect else EXTRA))
    effects = ALL_EFFECTS if every_effect else EFFECTS
    for eff in later:
        vals.update(LATER_EXTRA[eff])
    effects = effects + list(later)
    if kind == "instant":
        vals["L"] = 0.0
    if kind not in VOLTAGE_KINDS:
        for n in ("R", "L", "km", "ke", "vmax", "vb"):
            vals.pop(n, None)
        effects = [e for e in effects if e not in ("back_emf", "voltage_saturation",
                                                    "brush_drop")]
    m = truth_model(vals, effects)
    if kind == "lumped":
        m.extra["lumped"] = True
    save_model(m, path)
    return m


def inputs(kind="v", window=(0.0, 30.0)):
    """(name, t, u) pairs: the triangle's first 30 s every 4th sample (4 ms: two internal steps,
    stick-slip at the reversal) and the 1.5 V step. Torque inputs scaled by km/R. ``window``:
    the triangle's stretch [s] (Octave steps the exported code a sample at a time: its tests
    take 8-22 s, the top speed at 10 s and the reversal through zero at 20 s)."""
    tri = read_log(FIX / "triangle.csv")
    a, b = (int(np.searchsorted(tri.t, x)) for x in window)
    step = read_log(FIX / "step_1.5V.csv")
    out = [("triangle", tri.t[a:b:4] - tri.t[a], tri.u[a:b:4]), ("step", step.t, step.u)]
    if kind == "tau":
        out = [(name, t, u * PAPER["km"] / PAPER["R"]) for name, t, u in out]
    return out


def reference(t, u, model, kind):
    """What pmdcid simulate predicts: (i, omega, theta) as the sensors read them."""
    sim = simulate(t, u, model, torque_driven=kind not in VOLTAGE_KINDS)
    return np.column_stack([sim.i, sim.omega, sim.theta])


def rel_error(y, ref):
    """max |y - ref| / max |ref| per column; NaN columns must be NaN in both (then 0)."""
    out = []
    for k in range(ref.shape[1]):
        if np.isnan(ref[:, k]).all():
            assert np.isnan(y[:, k]).all()
            out.append(0.0)
        else:
            out.append(float(np.max(np.abs(y[:, k] - ref[:, k])) / np.max(np.abs(ref[:, k]))))
    return out


def dt_of(t):
    return float((t[-1] - t[0]) / (len(t) - 1))


#: a measured log (../shared/data/real, read in place: never copied into the repository): the
#: FRA233 rig's +-12 V sine through zero speed, 30 s at 1 kHz
REAL_LOG = FIX.parents[2] / "shared" / "data" / "real" / "fra233-2025-pboon" / "sine_1.csv"
#: a model of about that rig's size (R and L as the group measured them; km = ke from the
#: 21 rad/s per V slope; bc from the 1.5-2 V it needs to start), voltage-driven, no dead zone
RIG = {"R": 3.18, "L": 2.84e-3, "km": 0.045, "ke": 0.045, "J": 2e-5, "bv": 5e-5, "bc": 0.02,
       "dz": 0.0}


def real_input():
    """(t, v) of :data:`REAL_LOG`; the test is skipped when ../shared is absent."""
    import pytest

    if not REAL_LOG.exists():
        pytest.skip(f"no measured log at {REAL_LOG}")
    log = read_log(REAL_LOG)
    return log.t, log.u


def rig_model(path):
    """:data:`RIG` with its back-EMF, saved at ``path``."""
    m = truth_model(dict(RIG), ["back_emf"])
    save_model(m, path)
    return m
