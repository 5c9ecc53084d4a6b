"""Closed-loop rigs: micromouse-pid and EMPS with their controllers known (``--controller``).

    python -m bench.closedloop [micromouse|emps]   # the figures of docs/real-data.md, emps.md

- **micromouse-pid** (../shared/data/real/micromouse-pid, loop-timed 2-13 ms): fitted on the
  1 ms and 10 ms controller periods, predicting the 2 ms and 5 ms runs; held-out speed NRMSE of
  the logged-output route (each run simulated open loop from its logged command), of the
  controller route (each run's closed loop simulated from its reference), and the linear
  first-order-with-offset baseline (bench/realdata.py) on the logged command.
- **EMPS**: the authors' parameters and the controller route's estimate, each simulated in
  closed loop from the reference (the PD controller of EMPS_Description.txt eq. 6-7): relative
  position and velocity errors [%] beside the authors' 0.008 % and 0.479 % (validation file).
- **EMPS, the benchmark's score** (``python -m bench.closedloop emps-rmse``): the test
  position RMSE in mm with 20 samples to initialise (:func:`benchmark_rmse_mm`), open loop on
  the logged force and, for comparison, in closed loop, for the authors' parameters,
  fit-nonlinear, diagnose and identify on the estimation file (docs/examples/emps.md).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.realdata import SHARED, fit_linear, linear_sim, nrmse  # noqa: E402

MICROMOUSE = SHARED / "real" / "micromouse-pid"
EMPS = SHARED / "emps"
FIT = ("pid_delay_1ms.csv", "pid_delay_10ms.csv")
HELD = ("pid_delay_2ms.csv", "pid_delay_5ms.csv")
#: the micromouse's speed loop (opatiny/micromouse, matlab/controllerDelayImpact.m and the logs:
#: every step the PWM command moves by floor(0.02 x error in rpm) counts of 7.4 V / 255):
#: incremental, per step, quantised down to one count
MICROMOUSE_SPEC = {"type": "PI", "kp": 0, "ki": 0.02 * 60 / (2 * math.pi) * 7.4 / 255,
                   "form": "velocity", "integrate": "steps", "quantum": 7.4 / 255,
                   "umin": -7.4, "umax": 7.4}
#: EMPS (EMPS_Description.txt eq. 6-7): nu = kp kv (qr - q) - kv dq_f/dt, q_f the 2-tap mean,
#: |nu| <= 10 V, force = gtau nu; the validation file's pulses are added to nu
KP, KV, GTAU = 160.18, 243.45, 35.15065188
EMPS_SPEC = {"type": "PID", "kp": KP * KV, "kd": KV, "measured": "theta",
             "reference": "qg_ref_m", "derivative": "measurement", "dfilter": [0.5, 0.5],
             "umin": -10, "umax": 10, "scale": GTAU}
AUTHORS = {"J": 95.1089, "bv": 203.5034, "bc": 20.3935, "tau0": -3.1648}


# -- the loop-timed logs on their own instants: the controller route steps each logged period as
# it was (pmdcid.io puts them on a uniform grid, which the other routes use: io/clock.py) -------
def read_loop_timed(path):
    """A loop-timed micromouse CSV as a :class:`~pmdcid.io.Log` on its own (non-uniform) times."""
    from pmdcid.io.logs import Log

    a = np.loadtxt(path, delimiter=",", comments="#", skiprows=2)
    t, v, w, r = a.T
    return Log(Path(path).name, t - t[0], {"v": v, "omega": w}, extra={"omega_ref": r})


def uniform_log(path):
    """The log as every command reads it: on a uniform grid of its median period, the input
    held, the measurements interpolated (:func:`pmdcid.io.read_log`, io/clock.py)."""
    import warnings

    from pmdcid.io import read_log

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the one-line resampling note, once per log
        return read_log(path)




def micromouse(folder: Path = MICROMOUSE) -> dict:
    """Held-out speed NRMSE per run: linear baseline, logged-output route, controller route."""
    from pmdcid.identify.runners import per_volt, stage_nonlinear
    from pmdcid.model import Model
    from pmdcid.model.lumped import mark_lumped
    from pmdcid.simulate import param_values, simulate_values
    from pmdcid.simulate.closedloop import simulate_closed_loop
    from pmdcid.simulate.controller import controller_from_dict

    spec = controller_from_dict(MICROMOUSE_SPEC)
    fit_raw = [read_loop_timed(folder / n) for n in FIT]
    held_raw = [read_loop_timed(folder / n) for n in HELD]
    held = [uniform_log(folder / n) for n in HELD]
    fit_grid = [uniform_log(folder / n) for n in FIT]
    lin = fit_linear(fit_grid)
    out = {"linear": [nrmse(linear_sim(lin, lg), lg["omega"]) for lg in held]}
    for route, logs, ctrl in (("logged output", fit_grid, None),
                              ("controller", fit_raw, spec)):
        model = Model()
        mark_lumped(model)
        res = stage_nonlinear(logs, model, controller=ctrl)
        per_volt(res)
        res.apply(model)
        vals = param_values(model, True)
        out[route + ", open loop"] = [
            nrmse(simulate_values(lg.t, lg["v"], vals, True).omega, lg["omega"]) for lg in held]
        out[route + ", closed loop"] = [
            nrmse(simulate_closed_loop(lg.t, vals, spec, lg.extra["omega_ref"], True,
                                       logged_u=lg["v"]).omega, lg["omega"])
            for lg in held_raw]
    return out


def emps_errors(log, values: dict, spec) -> tuple[float, float, float]:
    """Closed-loop relative errors [%] of ``values`` on ``log``: position (all samples),
    velocity (the benchmark's filtered speed, first 49 samples left out) and force (the
    simulated controller's against the logged, all samples)."""
    from pmdcid.identify.openloop import EMPS_SKIP, measured_speed
    from pmdcid.simulate import neutral_values
    from pmdcid.simulate.closedloop import feedforward_of, reference_of, simulate_closed_loop

    vals = {**neutral_values(), "R": 1.0, "L": 1.0, "km": 1.0, **values}
    sim = simulate_closed_loop(log.t, vals, spec, reference_of(log, spec), True,
                               logged_u=log.u, feedforward=feedforward_of(log, spec))
    q = log["theta"]
    pos = 100 * np.linalg.norm(sim.theta - q) / np.linalg.norm(q)
    v = measured_speed(log)[EMPS_SKIP:]
    vel = 100 * np.linalg.norm(sim.omega_true[EMPS_SKIP:] - v) / np.linalg.norm(v)
    force = 100 * np.linalg.norm(sim.u - log.u) / np.linalg.norm(log.u)
    return float(pos), float(vel), float(force)


def emps(folder: Path = EMPS) -> dict:
    """The authors' parameters and the controller route's fit, in closed loop on both files."""
    from pmdcid.identify.runners import stage_nonlinear
    from pmdcid.io import parse_mapping, read_log
    from pmdcid.model import Model
    from pmdcid.simulate.controller import controller_from_dict

    m = parse_mapping(["t=t_s", "tau=force_N", "theta=qm_meas_m"])
    train = read_log(folder / "emps_train_DATA_EMPS.csv", m)
    test = read_log(folder / "emps_test_DATA_EMPS_PULSES.csv", m)
    spec = controller_from_dict(EMPS_SPEC)
    pulses = controller_from_dict({**EMPS_SPEC, "feedforward": "pulse_in_vir_units"})
    res = stage_nonlinear([train], Model(), controller=spec)
    fitted = {k: e.value for k, e in res.estimates.items()}
    out = {}
    for label, vals in (("authors", AUTHORS), ("controller route", fitted)):
        out[label] = {"values": vals, "estimation": emps_errors(train, vals, spec),
                      "validation": emps_errors(test, vals, pulses)}
    return out


# -- the EMPS benchmark's own score (nonlinearbenchmark.org; the nonlinear_benchmarks package:
# its EMPS loader gives the test file state_initialization_window_length = 20, its submission
# example scores 1000 * RMSE(test.y[n:], y_model[n:]) with y the measured position) -----------
#: samples at the start of the test file that initialise the model's state, not scored
N_INIT = 20


def benchmark_rmse_mm(measured, simulated, n_init: int = N_INIT) -> float:
    """The EMPS benchmark's score [mm]: the root mean square of simulated minus measured
    position [m] over samples ``n_init``, ``n_init`` + 1, ... to the end, times 1000. The first
    ``n_init`` samples (20 on the benchmark's test file) may initialise the model and are not
    scored."""
    e = np.asarray(simulated, float)[n_init:] - np.asarray(measured, float)[n_init:]
    return float(1000.0 * np.sqrt(np.mean(e ** 2)))


def initial_state(log, vals: dict, n_init: int = N_INIT) -> tuple[float, float, float]:
    """The state (i = 0, speed [m/s], position [m]) at the log's first sample, read from its
    first ``n_init`` measured positions only, as the benchmark allows: the start (q0, v0) whose
    open-loop simulation of ``vals`` on the logged force fits those positions best (least
    squares), started from a quadratic through them."""
    from pmdcid.simulate import simulate_values

    t, q, u = log.t[:n_init], np.asarray(log["theta"][:n_init], float), log.u[:n_init]
    c = np.polyfit(t - t[0], q, 2)

    def resid(x):
        sim = simulate_values(t, u, vals, True, x0=(0.0, x[1], x[0]), dt=log.dt)
        return sim.theta - q

    sol = least_squares(resid, [c[2], c[1]], x_scale=[1e-3, 1e-2])
    return 0.0, float(sol.x[1]), float(sol.x[0])


def emps_rmse_mm(log, model, spec=None) -> float:
    """:func:`benchmark_rmse_mm` of ``model`` on ``log``, from :func:`initial_state`: open
    loop on the logged force (``spec`` None: the benchmark's task, input vir, output the
    position), or in closed loop under ``spec`` from the logged reference (the benchmark does
    not give the model the reference)."""
    from pmdcid.simulate import param_values, simulate_values
    from pmdcid.simulate.closedloop import feedforward_of, reference_of, simulate_closed_loop

    vals = param_values(model, True)
    x0 = initial_state(log, vals)
    if spec is None:
        sim = simulate_values(log.t, log.u, vals, True, x0=x0)
    else:
        sim = simulate_closed_loop(log.t, vals, spec, reference_of(log, spec), True, x0,
                                   logged_u=log.u, feedforward=feedforward_of(log, spec))
    return benchmark_rmse_mm(log["theta"], sim.theta)


def emps_models(train) -> dict:
    """The models scored: the authors' parameters, and fit-nonlinear, diagnose (after
    fit-nonlinear: docs/examples/emps.md's commands) and identify, each on ``train`` only."""
    from pmdcid.diagnose import diagnose
    from pmdcid.identify.runners import stage_nonlinear
    from pmdcid.model import Model
    from pmdcid.pipeline import identify

    authors = Model()
    for k, v in AUTHORS.items():
        authors.set(k, v)
    authors.add_effect("torque_offset")
    fitted = Model()
    stage_nonlinear([train], fitted).apply(fitted)  # as the command runs it
    return {"authors' parameters": authors, "fit-nonlinear": fitted,
            "fit-nonlinear + diagnose": diagnose([train], fitted).model,
            "identify": identify([train], Model()).model}


def emps_scores(folder: Path = EMPS) -> dict:
    """Per model: the benchmark's score [mm] on the test (validation) file open loop, the same
    on the estimation file, the test file's score in closed loop, and the benchmark's open-loop
    velocity error [%] on the test file (:func:`pmdcid.identify.openloop.velocity_error`)."""
    from pmdcid.identify.openloop import velocity_error
    from pmdcid.io import parse_mapping, read_log
    from pmdcid.simulate.controller import controller_from_dict

    m = parse_mapping(["t=t_s", "tau=force_N", "theta=qm_meas_m"])
    train = read_log(folder / "emps_train_DATA_EMPS.csv", m)
    test = read_log(folder / "emps_test_DATA_EMPS_PULSES.csv", m)
    pulses = controller_from_dict({**EMPS_SPEC, "feedforward": "pulse_in_vir_units"})
    return {label: {"test": emps_rmse_mm(test, model), "estimation": emps_rmse_mm(train, model),
                    "test, closed loop": emps_rmse_mm(test, model, pulses),
                    "velocity error": velocity_error(test, model)}
            for label, model in emps_models(train).items()}


def main(argv=None) -> int:
    only = (argv if argv is not None else sys.argv[1:])[:1]
    if MICROMOUSE.is_dir() and only in ([], ["micromouse"]):
        for k, v in micromouse().items():
            print(f"micromouse {k:28s} " + "  ".join(f"{x:.3f}" for x in v)
                  + f"   mean {np.mean(v):.3f}")
    if EMPS.is_dir() and only in ([], ["emps"]):
        for label, r in emps().items():
            vals = ", ".join(f"{k} {v:.5g}" for k, v in r["values"].items())
            print(f"EMPS {label}: {vals}")
            for f in ("estimation", "validation"):
                print(f"  {f}: position {r[f][0]:.4f} %, velocity {r[f][1]:.3f} %, "
                      f"force {r[f][2]:.2f} %")
    if EMPS.is_dir() and only == ["emps-rmse"]:
        for label, r in emps_scores().items():
            print(f"EMPS {label:26s} " + ", ".join(
                f"{k} {v:.3f} {'%' if k == 'velocity error' else 'mm'}" for k, v in r.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
