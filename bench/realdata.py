"""Real rigs: fit on some logs, predict the others, against a linear baseline and the repeat floor.

Used by ``make realbench`` (bench/realbench.py) and tests/system/test_real_rigs.py. The data are
read from ``../shared/data`` (never copied into the repository).

- **linear baseline**: a first-order model with an input offset, ``T w' = K (u - u0) - w``,
  fitted by simulation error (exact zero-order hold) on the same fit logs;
- **repeat floor**: each held-out run predicted by the mean of its repeats (the other runs of
  the same protocol), the best any time-invariant model of the input can be expected to do;
- **paper**: fit-mechanical on the step logs, then fit-nonlinear on the rich logs (priors from
  the steps), as the paper's stage sequence;
- **identify**: the whole rig in one call (:func:`pmdcid.pipeline.identify`).

Every error is the held-out speed NRMSE (RMS error / std of the measured speed), each run
simulated from its measured first samples.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


@dataclass
class Rig:
    """One rig: folder, fit logs by protocol class, held-out logs grouped by protocol."""

    name: str
    folder: Path
    steps: list[str]
    rich: list[str]
    heldout: dict[str, list[str]]  # protocol -> its runs (repeats)
    mapping: list[str] = field(default_factory=list)
    why: str = ""


def rigs(shared: Path = SHARED) -> list[Rig]:
    """The rigs under ``shared/real`` and EMPS, with the logs each fits on and predicts."""
    real = shared / "real"
    g04 = real / "fra233-g04"
    pb = real / "fra233-2025-pboon"
    l298 = real / "guanlunlu-l298n"
    out = [
        Rig("fra233-g04", g04, ["step_1.csv", "step_2.csv"], ["ramp_1.csv", "ramp_2.csv"],
            {p: [f"{p}_{k}.csv" for k in range(1, 7)] for p in ("sine", "chirp", "stair")},
            why="the course's own protocol: steps and ramps to fit, the other protocols "
                "(six repeats each) held out"),
        Rig("fra233-2025-pboon", pb, ["step_4.csv", "step_8.csv", "step_100000.csv"],
            ["ramp_100000.csv", "ramp_0-6.csv"],
            {p: [f"{p}_{f}.csv" for f in (1000, 10000, 100000)]
             for p in ("sine", "chirp", "stair", "triangle")},
            why="steps and ramps at the default 100 kHz PWM to fit; the other protocols at "
                "1, 10 and 100 kHz held out (slower carriers ripple the speed: not repeats)"),
        Rig("guanlunlu-l298n", l298, ["step_6V_1.csv", "step_12V_1.csv", "step_24V_1.csv"], [],
            {f"step_{v}V": [f"step_{v}V_{k}.csv" for k in (2, 3)] for v in (6, 12, 24)},
            why="the first run of each voltage to fit, the two other repeats held out"),
    ]
    ev3 = real / "lego-ev3"
    out.append(Rig("lego-ev3", ev3,
                   [f"step_{s}{d}.csv" for d in range(10, 101, 10) for s in "+-"], [],
                   {f"sine_{k}pi": [f"sine_{k}pi.csv"] for k in (1, 2, 3)},
                   why="loop-timed samples (4-18 ms, resampled on read): the duty steps to fit, "
                       "the three sines (0.5, 1, 1.5 Hz, through zero speed) held out"))
    emps = shared / "emps"
    out.append(Rig("EMPS", emps, [], ["emps_train_DATA_EMPS.csv"],
                   {"pulses": ["emps_test_DATA_EMPS_PULSES.csv"]},
                   ["t=t_s", "tau=force_N", "theta=qm_meas_m"],
                   why="the benchmark's estimation file to fit, its validation file held out"))
    return [r for r in out if r.folder.is_dir()]


def read(rig: Rig, names) -> list:
    from pmdcid.io import parse_mapping, read_log

    m = parse_mapping(rig.mapping)
    return [read_log(rig.folder / n, m) for n in names]


def nrmse(sim, meas) -> float:
    ok = np.isfinite(sim) & np.isfinite(meas)
    sd = float(np.std(meas[ok]))
    return float(np.sqrt(np.mean((sim[ok] - meas[ok]) ** 2)) / sd) if sd > 0 else math.nan


# -- the linear baseline ------------------------------------------------------------------------
def linear_sim(x, log) -> np.ndarray:
    """First order with input offset, exact ZOH, from the measured first speed [rad/s]."""
    K, T, u0 = x
    a = math.exp(-log.dt / max(T, 1e-9))
    from scipy.signal import lfilter

    w0 = float(np.mean(log["omega"][:5]))
    drive = K * (np.asarray(log.u, float) - u0) * (1 - a)
    y, _ = lfilter([0.0, 1.0], [1.0, -a], drive, zi=[a * w0])
    return y


def fit_linear(logs) -> np.ndarray:
    """K [rad/s per input unit], T [s], u0 [input unit] by simulation error on ``logs``."""
    u = np.concatenate([lg.u for lg in logs])
    w = np.concatenate([lg["omega"] for lg in logs])
    big = np.abs(u) > 0.3 * np.max(np.abs(u))
    K0 = float(np.median(w[big] / u[big])) if big.any() else 1.0
    x0 = np.array([K0, 0.05, 0.0])

    def resid(x):
        return np.concatenate([(linear_sim(x, lg) - lg["omega"]) / np.std(lg["omega"])
                               for lg in logs])

    sol = least_squares(resid, x0, x_scale=[abs(K0) or 1.0, 0.05, 0.1 * np.max(np.abs(u))],
                        bounds=([-np.inf, 1e-5, -np.inf], [np.inf, 100.0, np.inf]))
    # the offset helps a one-sided input and can hurt a bipolar one: without it too, and the
    # better of the two on the fit logs (never chosen by the held-out logs)
    plain = least_squares(lambda x: resid([x[0], x[1], 0.0]), x0[:2],
                          x_scale=[abs(K0) or 1.0, 0.05],
                          bounds=([-np.inf, 1e-5], [np.inf, 100.0]))
    if 2 * plain.cost < 2 * sol.cost:
        return np.array([plain.x[0], plain.x[1], 0.0])
    return sol.x


# -- the repeat floor ---------------------------------------------------------------------------
def repeat_floor(runs) -> list[float]:
    """Each run's NRMSE against the mean of the other runs of its protocol (same samples)."""
    if len(runs) < 2:
        return [math.nan] * len(runs)
    n = min(lg.n for lg in runs)
    W = np.array([lg["omega"][:n] for lg in runs])
    out = []
    for k in range(len(runs)):
        mean = np.mean(np.delete(W, k, axis=0), axis=0)
        out.append(nrmse(mean, W[k]))
    return out


# -- the models ---------------------------------------------------------------------------------
def predict(model, log) -> float:
    from pmdcid.simulate.measured import simulate_for

    return nrmse(simulate_for(log, model).omega, log["omega"])


def paper_sequence(rig: Rig, km=None):
    """fit-mechanical on the steps, then fit-nonlinear on the rich logs (priors); first
    fit-electrical on the logs with current (free-running: R, L, ke), and torque steps to
    fit-nonlinear (fit-mechanical reads voltage steps). Step logs fit-mechanical refuses with
    its pointer to fit-nonlinear (no held step, plateaus too short) go to fit-nonlinear, as a
    user following the message runs it."""
    from pmdcid.identify.runners import stage_electrical
    from pmdcid.model import Model
    from pmdcid.model.lumped import mark_lumped, wants_lumped
    from pmdcid.pipeline import _mechanical, _nonlinear

    model = Model()
    steps, rich = read(rig, rig.steps), read(rig, rig.rich)
    with_current = [lg for lg in steps + rich if lg.has("i") and lg.drive == "v"]
    if with_current:  # the paper's first stage: R, L (and ke, km = ke: free-running logs)
        stage_electrical(with_current, model).apply(model)
    if steps and all(lg.drive == "tau" for lg in steps):  # fit-mechanical reads voltage steps
        steps, rich = [], steps + rich
    if wants_lumped(steps + rich, model):
        mark_lumped(model)
    if steps:  # the logs fit-mechanical does not use, it says fit-nonlinear fits (one run:
        # inside the comprehension's condition it ran once per step log)
        used = _stage_into(model, steps, _mechanical)
        rich = rich + [lg for lg in steps if lg.path not in used]
    if rich:
        _stage_into(model, rich, _nonlinear(True))
    return model


def _stage_into(model, logs, stage) -> set:
    """Run one stage on ``logs``, write its result into ``model``; the paths of the logs it
    used (fit-mechanical's with a step it fitted: none when it refused every step with its
    message pointing to fit-nonlinear, which a user runs next; a log whose every step it left
    out, unsettled or still, is not among them: its warning points there too)."""
    from pmdcid.errors import NoStepError
    from pmdcid.identify.runners import per_volt
    from pmdcid.model.lumped import is_lumped

    try:
        res = stage(logs, model)
    except NoStepError:  # its message points to fit-nonlinear, the user's next stage
        return set()
    if is_lumped(model):  # per-volt units in the table, as identify's stages
        per_volt(res)
    res.apply(model)
    return ({s.path for s in getattr(res, "steps", []) if not s.note}
            or {lg.path for lg in logs})


def identify_rig(rig: Rig, diagnose: bool = True):
    from pmdcid.model import Model
    from pmdcid.pipeline import identify

    logs = read(rig, rig.steps + rig.rich)
    return identify(logs, Model(), run_diagnose=diagnose).model


def identify_before_after(logs):
    """identify's model on ``logs`` before diagnose and after it, from one run: (before, after;
    ``after`` is ``before`` when diagnose did not run), as ``pmdcid identify`` does it."""
    from pmdcid.model import Model
    from pmdcid.pipeline import _diagnose, identify

    res = identify(logs, Model(), run_diagnose=False)
    before = res.model.copy()
    if any(name.startswith("joint") for name, _ in res.stages):
        moving = [lg for kind in ("step", "rich")  # in identify's order
                  for lg, p in zip(logs, res.plan, strict=True) if p.kind == kind]
        _diagnose(res, moving)
    return before, res.model


def diagnose_rises(result: dict, before: str = "base", after: str = "identify",
                   limit: float = 0.05) -> list[str]:
    """The held-out runs whose speed NRMSE diagnose raised by more than ``limit`` (relative)."""
    return [f"{row['log']}: {row[before]:.3f} -> {row[after]:.3f}"
            for row in result["rows"] if row[after] > (1.0 + limit) * row[before]]


def evaluate(rig: Rig, models: dict) -> dict:
    """Held-out NRMSE per run for each model, the linear baseline and the repeat floor."""
    fit_logs = read(rig, rig.steps + rig.rich)
    lin = fit_linear(fit_logs)
    rows = []
    for proto, names in rig.heldout.items():
        runs = read(rig, names)
        floor = repeat_floor(runs)
        for name, lg, fl in zip(names, runs, floor, strict=True):
            row = {"log": name, "protocol": proto, "floor": fl,
                   "linear": nrmse(linear_sim(lin, lg), lg["omega"])}
            for label, model in models.items():
                row[label] = predict(model, lg)
            rows.append(row)
    return {"rig": rig.name, "why": rig.why, "fit": rig.steps + rig.rich, "rows": rows,
            "linear_params": lin.tolist()}


def lag_drift(rig: Rig, model) -> list[str]:
    """The held-out runs whose speed lags ``model`` by an amount that changes along the run
    (:mod:`pmdcid.diagnose.timing`), one description each."""
    from pmdcid.diagnose.timing import describe_lag, lag_profile
    from pmdcid.io.derive import noise_std
    from pmdcid.simulate.measured import simulate_for

    out = []
    for names in rig.heldout.values():
        for name, lg in zip(names, read(rig, names), strict=True):
            if not lg.has("omega") or "omega" in lg.derived:
                continue
            om = np.asarray(lg["omega"], float)
            prof = lag_profile(lg.t, simulate_for(lg, model).omega, om, noise_std(om))
            if prof is not None and prof.varies:
                out.append(describe_lag(name, prof))
    return out


def summarise(result: dict, labels) -> dict:
    """Means over the held-out runs and the target max(linear/2, 1.2 floor)."""
    rows = result["rows"]
    mean = {}
    for k in ["linear", "floor", *labels]:
        vals = [r[k] for r in rows if math.isfinite(r[k])]
        mean[k] = float(np.mean(vals)) if vals else math.nan
    floor = mean["floor"] if math.isfinite(mean["floor"]) else 0.0
    mean["target"] = max(0.5 * mean["linear"], 1.2 * floor)
    return mean
