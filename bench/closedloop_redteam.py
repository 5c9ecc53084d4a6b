"""Red team: closed-loop logs as robotics users log them, run through the CLI as a new user would.

    python -m bench.closedloop_redteam [a b c ...] [--seed N] [--keep DIR]

Synthetic rigs (no data copied: every log is simulated here by
:func:`pmdcid.simulate.kernel.run_kernel` with a known motor under a firmware-like controller,
``numpy.random.default_rng(seed)``):

- **a** a PI speed loop at 1 kHz on a small gear motor (SI: J 2e-5 kg m^2, Coulomb friction and
  a dead zone), the speed from an encoder as counts per controller period (quantised, 1000
  counts/rev: 60 rpm per count per ms), the quantised speed fed back, the output an integer PWM
  duty -255..255 of a supply 5 % above the nominal 12 V the user maps; runs at set-point steps,
  a staircase through zero and sines; columns ``t`` [ms], ``targetSpeed`` [rpm], ``speed``
  [rpm], ``pwm``.
- **b** the same loop logged by a slower task: rows 2-13 ms apart (integer ms), the controller
  still at 1 kHz (its period differs from the log's).
- **c** a PID position loop at 1 kHz on a current-controlled drive (EMPS-like): the encoder
  angle in counts (4096/rev), the set-point a smooth move profile in counts, the current command
  in A logged; the user maps tau = current x km (datasheet).
- **d** (``a+``, ``b+``, ``c+``) each with the controller known: ``--controller`` given to
  identify and to simulate.

For each: identify on some runs (the CLI of this tree, the user's own column names mapped with
``-c``), the route line, held-out speed NRMSE of ``simulate --x0 measured`` on the logged input
(and, with the controller, in closed loop from the reference) against the linear
first-order-with-offset baseline (bench/realdata.py), each parameter's error in its standard
errors (truth per logged volt for the lumped gear motor: the supply's 5 % is in it), diagnose's
additions, and report's exit status. Failures are listed with a one-line reproduction.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.realdata import fit_linear, linear_sim, nrmse  # noqa: E402

RPM = 2 * math.pi / 60
#: the gear motor of cases a/b, SI at the encoder's shaft: tau_m = J R/(km^2 + bv R) = 0.2 s
GEAR = {"R": 4.0, "L": 1.5e-3, "km": 0.02, "J": 2e-5, "bv": 2e-6, "bc": 2e-3}
#: the H-bridge's dead band: a duty below this many PWM counts applies no voltage (the dead zone
#: on the drive, as the lumped model without an electrical lag holds it: per logged volt)
DEADBAND = 12
VNOM, SUPPLY = 12.0, 1.05  # the user maps pwm x 12/255; the battery gives 5 % more
CPR_SPEED = 1000  # encoder counts per revolution (cases a/b)
#: the firmware's PI in PWM counts per rpm (ki per second): crossover ~30 rad/s, zero at 1/tau_m
KP_RPM, KI_RPM = 0.27, 1.35
#: the position rig of case c, SI: J [kg m^2], bv [N m s/rad], bc [N m]; km of the drive
AXIS = {"J": 5e-5, "bv": 1e-4, "bc": 0.01}
KM_AXIS = 0.05
CPR_POS = 4096
#: the firmware's PID in A per rad (ki per second, kd in seconds), D on the measurement,
#: 2-tap mean on its difference, +-3 A
PID_POS = {"kp": 2.5, "ki": 10.0, "kd": 0.07, "imax": 3.0}


# -- the motor stepped one controller period at a time ------------------------------------------
class Plant:
    """A motor (SI values) stepped over held inputs by the one kernel."""

    def __init__(self, vals: dict, torque_driven: bool):
        from pmdcid.model import Model
        from pmdcid.simulate import param_values, param_vector

        m = Model()
        for k, v in vals.items():
            m.set(k, v, stage="truth")
        if not torque_driven:  # a real motor's counter-EMF: ke = km in SI
            m.add_effect("back_emf")
            m.set("ke", vals["km"], stage="truth")
        self.p = param_vector(param_values(m, torque_driven))
        self.td = torque_driven
        self.x = np.zeros(3)

    def step(self, u: float, h: float) -> np.ndarray:
        from pmdcid.simulate.kernel import run_kernel

        x = run_kernel(np.array([u, u]), h, self.p, self.td, None, self.x)
        self.x = x[1].copy()
        return self.x


def _trunc(x: float) -> float:
    """C's (int) cast: toward zero."""
    return float(math.trunc(x))


def speed_loop_run(rng, ref_rpm, seconds: float, log_gaps=None) -> dict:
    """Case a (``log_gaps`` None: a row per 1 ms controller step) or b (rows when a logger task
    wakes, ``log_gaps`` [ms] apart): the firmware's PI on the encoder's counts per period."""
    plant = Plant(GEAR, False)
    dt = 1e-3
    n = int(round(seconds / dt))
    count_prev = 0
    integ, pwm = 0.0, 0.0
    theta0 = rng.uniform(0, 2 * math.pi)  # where the encoder's count grid sits
    rows = []
    next_log = 0
    for k in range(n):
        x = plant.x
        count = math.floor((x[2] + theta0) * CPR_SPEED / (2 * math.pi))
        speed_rpm = (count - count_prev) * 60.0 / (CPR_SPEED * dt) if k else 0.0
        count_prev = count
        target = ref_rpm(k * dt)
        err = target - speed_rpm
        raw = KP_RPM * err + integ + KI_RPM * err * dt
        if abs(raw) < 255 or raw * err < 0:  # the firmware's anti-windup: clamp
            integ += KI_RPM * err * dt
        pwm = max(-255.0, min(255.0, _trunc(KP_RPM * err + integ)))
        if log_gaps is None or k >= next_log:
            rows.append((k, target, speed_rpm, pwm))
            if log_gaps is not None:
                next_log = k + int(rng.integers(log_gaps[0], log_gaps[1] + 1))
        applied = 0.0 if abs(pwm) < DEADBAND else pwm * SUPPLY * VNOM / 255.0
        plant.step(applied, dt)
    t, target, speed, pwm = (np.array(c) for c in zip(*rows, strict=True))
    return {"t": t, "targetSpeed": target, "speed": speed, "pwm": pwm}


def position_loop_run(rng, ref_rad, seconds: float) -> dict:
    """Case c: the firmware's PID on the encoder angle, the drive making the commanded current."""
    plant = Plant(AXIS, True)
    dt = 1e-3
    n = int(round(seconds / dt))
    g = PID_POS
    integ, hist = 0.0, []
    theta0 = rng.uniform(0, 2 * math.pi)
    c0 = math.floor(theta0 * CPR_POS / (2 * math.pi))
    rows = []
    for k in range(n):
        count = math.floor((plant.x[2] + theta0) * CPR_POS / (2 * math.pi)) - c0
        q = count * 2 * math.pi / CPR_POS
        target = ref_rad(k * dt)
        err = target - q
        hist = (hist + [q])[-3:]
        d = 0.0 if len(hist) < 3 else -((hist[2] + hist[1]) - (hist[1] + hist[0])) / (2 * dt)
        raw = g["kp"] * err + integ + g["ki"] * err * dt + g["kd"] * d
        if abs(raw) < g["imax"] or raw * err < 0:
            integ += g["ki"] * err * dt
        i_cmd = max(-g["imax"], min(g["imax"], g["kp"] * err + integ + g["kd"] * d))
        rows.append((k * dt, round(target * CPR_POS / (2 * math.pi)), count, i_cmd))
        plant.step(i_cmd * KM_AXIS, dt)
    t, target, enc, cur = (np.array(c) for c in zip(*rows, strict=True))
    return {"t": t, "targetPosition": target, "encoder": enc, "current_cmd": cur}


# -- the runs a user records ---------------------------------------------------------------------
def _steps(levels, hold):
    levels = list(levels)
    return lambda t: levels[min(int(t / hold), len(levels) - 1)]


def _sine(mean, amp, hz):
    return lambda t: mean + amp * math.sin(2 * math.pi * hz * t)


def speed_profiles(rng):
    """(name, reference [rpm], seconds): fit on the first three, predict the others."""
    return [
        ("steps_up", _steps([0, 1000, 2500, 1500, 3000], 0.6), 3.0),
        ("through_zero", _steps([0, 800, -800, 1500, -1500, 300, -300], 0.5), 3.5),
        ("sine_1hz", _sine(1500, 1200, 1.0), 3.0),
        ("steps_mixed", _steps(rng.uniform(-3000, 3000, 6).round(-1), 0.5), 3.0),
        ("sine_0p5hz_zero", _sine(0, 1500, 0.5), 4.0),
        ("steps_small", _steps([0, 400, 200, 600, 100], 0.6), 3.0),
    ]


def _move(segments):
    """A smooth point-to-point profile [rad]: (t_start, t_end, q_from, q_to) cosine moves."""
    def ref(t):
        q = segments[0][2]
        for t0, t1, a, b in segments:
            if t >= t1:
                q = b
            elif t >= t0:
                q = a + (b - a) * (1 - math.cos(math.pi * (t - t0) / (t1 - t0))) / 2
        return q
    return ref


def position_profiles(rng):
    """(name, reference [rad], seconds): fit on the first three, predict the others."""
    return [
        ("moves_a", _move([(0.2, 0.8, 0, 6), (1.2, 1.6, 6, 2), (2.0, 2.9, 2, 12),
                           (3.2, 3.6, 12, 0)]), 4.0),
        ("moves_b", _move([(0.1, 0.5, 0, -4), (0.8, 1.8, -4, 8), (2.2, 2.5, 8, 5),
                           (2.8, 3.7, 5, 0)]), 4.0),
        ("sweep", lambda t: 5 * math.sin(2 * math.pi * 0.4 * t) * min(t, 1.0), 4.0),
        ("moves_c", _move([(0.2, 0.6, 0, 3), (1.0, 2.0, 3, -9), (2.5, 3.0, -9, -3),
                           (3.3, 3.8, -3, 0)]), 4.0),
        ("slow_sine", lambda t: 8 * math.sin(2 * math.pi * 0.25 * t), 4.0),
    ]


# -- the cases -----------------------------------------------------------------------------------
@dataclass
class Case:
    name: str
    runs: list  # (name, columns)
    nfit: int
    maps: list  # -c arguments
    truth: dict  # parameter -> value in the model's units
    controller: str | None = None
    notes: list = field(default_factory=list)


def lumped_truth(vals: dict, supply: float = SUPPLY) -> dict:
    """The gear motor per logged (nominal) volt (model/lumped.py): J R/km, bv R/km + km (ke =
    km), bc R/km, each / supply (the battery's volt is ``supply`` logged volts); the driver's
    dead band in logged volts; tau_e = L/R."""
    r = vals["R"] / vals["km"] / supply
    return {"J": vals["J"] * r, "bv": vals["bv"] * r + vals["km"] / supply,
            "bc": vals["bc"] * r, "dz": DEADBAND * VNOM / 255, "tau_e": vals["L"] / vals["R"]}


SPEED_MAPS = ["t=t*ms", f"v=pwm*{VNOM:g}/255", "omega=speed*rpm", "omega_ref=targetSpeed*rpm"]


def speed_spec() -> str:
    """The firmware's PI as --controller: gains per rad/s of the mapped speed, in PWM counts,
    scaled to the mapped volts."""
    spec = {"type": "PI", "kp": KP_RPM / RPM, "ki": KI_RPM / RPM, "umin": -255, "umax": 255,
            "quantum": 1, "rounding": "zero", "scale": VNOM / 255}
    return json.dumps(spec)


def case(name: str, seed: int) -> Case:
    rng = np.random.default_rng(seed)
    base, known = name.rstrip("+"), name.endswith("+")
    if base in ("a", "b"):
        gaps = None if base == "a" else (2, 13)
        runs = [(n, speed_loop_run(rng, ref, s, gaps)) for n, ref, s in speed_profiles(rng)]
        spec = speed_spec() if known else None
        if known and base == "b":  # the controller runs every 1 ms, the log every 2-13 ms
            spec = json.dumps({**json.loads(spec), "period": 1e-3})
        return Case(name, runs, 3, SPEED_MAPS, lumped_truth(GEAR), spec)
    runs = [(n, position_loop_run(rng, ref, s)) for n, ref, s in position_profiles(rng)]
    maps = [f"theta=encoder*2*pi/{CPR_POS}", f"tau=current_cmd*{KM_AXIS:g}",
            f"theta_ref=targetPosition*2*pi/{CPR_POS}"]
    spec = None
    if known:
        g = PID_POS
        spec = json.dumps({"type": "PID", "kp": g["kp"], "ki": g["ki"], "kd": g["kd"],
                           "measured": "theta", "reference": "theta_ref",
                           "dfilter": [0.5, 0.5], "ulimit": g["imax"], "scale": KM_AXIS})
    return Case(name, runs, 3, maps, dict(AXIS), spec)


# -- running the CLI -----------------------------------------------------------------------------
#: the tree whose CLI runs (``--lib``: another checkout, e.g. main, for a before/after table)
LIB = [ROOT]


def cli(args, cwd) -> subprocess.CompletedProcess:
    code = ("import sys; from pmdcid.cli import main; sys.argv=['pmdcid']+sys.argv[1:]; main()")
    env = {"PYTHONPATH": str(LIB[0]), "PATH": "/usr/bin:/bin", "HOME": str(cwd),
           "PMDCID_THREADS": "1"}
    return subprocess.run([sys.executable, "-c", code, *map(str, args)], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=1800)


def write_runs(folder: Path, runs) -> list[Path]:
    paths = []
    for name, cols in runs:
        p = folder / f"{name}.csv"
        keys = list(cols)
        arr = np.column_stack([cols[k] for k in keys])
        np.savetxt(p, arr, delimiter=",", header=",".join(keys), comments="", fmt="%.10g")
        paths.append(p)
    return paths


@dataclass
class Outcome:
    case: str
    route: str = ""
    tool: float = math.nan
    closed: float = math.nan
    linear: float = math.nan
    sigmas: dict = field(default_factory=dict)
    added: list = field(default_factory=list)
    failures: list = field(default_factory=list)


def _check(res, what, out: Outcome, repro: str) -> bool:
    if res.returncode != 0 or "Traceback" in res.stderr:
        tb = "traceback" if "Traceback" in res.stderr else f"exit {res.returncode}"
        last = (res.stderr.strip().splitlines() or [""])[-1][:160]
        out.failures.append(f"{what}: {tb}: {last}  [{repro}]")
        return False
    return True


def read_mapped(path: Path, maps):
    import warnings

    from pmdcid.io import parse_mapping, read_log

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return read_log(path, parse_mapping(maps))


def held_nrmse(folder: Path, c: Case, held: list[Path], model: Path, closed: bool,
               out: Outcome) -> float:
    """Mean held-out speed NRMSE of ``simulate --x0 measured`` (open loop on the logged input,
    or with ``--controller`` in closed loop) against the log as the tool reads it."""
    sim_dir = folder / ("sim_closed" if closed else "sim")
    maps = [a for m in c.maps for a in ("-c", m)]
    extra = ["--controller", c.controller] if closed else []
    args = ["simulate", *held, "-m", model, "-o", sim_dir, "--x0", "measured", *maps, *extra]
    if len(held) == 1:
        args[args.index(sim_dir)] = sim_dir / held[0].name
    res = cli(args, folder)
    if not _check(res, "simulate" + (" --controller" if closed else ""), out,
                  f"pmdcid {' '.join(map(str, args[:1]))} HELD -m MODEL --x0 measured ..."):
        return math.nan
    errs = []
    for h in held:
        lg = read_mapped(h, c.maps)
        w = pd.read_csv(sim_dir / h.name, comment="#")["omega"].to_numpy(float)
        meas = lg["omega"] if len(w) == lg.n else _raw_speed(h, c)
        errs.append(nrmse(w, meas))
    return float(np.mean(errs))


def _raw_speed(path: Path, c: Case) -> np.ndarray:
    a = np.genfromtxt(path, delimiter=",", names=True)
    return a["speed"] * RPM if "speed" in a.dtype.names else np.gradient(a["encoder"])


def sigmas(model: Path, truth: dict) -> dict:
    """(estimate - truth) / stderr per parameter the model holds (nan: no stderr; an interval
    written instead of a stderr: 0 when the truth is inside it, else inf with the side), and the
    error in %. A lumped model without ``tau_e`` holds the electrical lag in J (model/lumped.py:
    J + (L/R) bv), and a torque offset's truth is 0."""
    pars = json.loads(model.read_text())["parameters"]
    truth = dict(truth, tau0=0.0)
    if "tau_e" in truth and "tau_e" not in pars:
        truth["J"] += truth["tau_e"] * truth["bv"]
    out = {}
    for k, v in truth.items():
        if k not in pars:
            continue
        e = pars[k]
        se = e.get("stderr") or math.nan
        pct = 100 * (e["value"] / v - 1) if v else math.nan
        if e.get("interval"):
            lo, hi = e["interval"]
            out[k] = (0.0 if lo <= v <= hi else math.copysign(math.inf, hi - v), pct)
            continue
        out[k] = ((e["value"] - v) / se if se and se > 0 else math.nan, pct)
    return out


def run_case(c: Case, folder: Path) -> Outcome:
    out = Outcome(c.name)
    paths = write_runs(folder, c.runs)
    fit, held = paths[:c.nfit], paths[c.nfit:]
    maps = [a for m in c.maps for a in ("-c", m)]
    ctrl = ["--controller", c.controller] if c.controller else []
    model = folder / "model.json"
    args = ["identify", *fit, "-m", model, "-o", folder / "report", *maps, *ctrl]
    res = cli(args, folder)
    (folder / "identify.log").write_text(res.stdout + "\n--stderr--\n" + res.stderr)
    repro = f"python -m bench.closedloop_redteam {c.name}  (identify)"
    if not _check(res, "identify", out, repro):
        return out
    route = [ln for ln in res.stdout.splitlines() + res.stderr.splitlines() if "route:" in ln]
    out.route = route[0].strip()[:200] if route else "(no route line)"
    if not route:
        out.failures.append(f"identify printed no route line  [{repro}]")
    out.sigmas = sigmas(model, c.truth)
    out.added = list(json.loads(model.read_text()).get("effects", []))
    fit_logs = [read_mapped(p, c.maps) for p in fit]
    held_logs = [read_mapped(p, c.maps) for p in held]
    if all(lg.has("omega") for lg in fit_logs + held_logs):
        lin = fit_linear(fit_logs)
        out.linear = float(np.mean([nrmse(linear_sim(lin, lg), lg["omega"])
                                    for lg in held_logs]))
    out.tool = held_nrmse(folder, c, held, model, False, out)
    if c.controller:
        out.closed = held_nrmse(folder, c, held, model, True, out)
    rep = cli(["report", *held, "-m", model, "-o", folder / "held_report", *maps], folder)
    _check(rep, "report (held-out)", out, f"pmdcid report HELD -m MODEL -o DIR ...  ({c.name})")
    return out


def fmt(o: Outcome) -> str:
    sig = ", ".join(f"{k} {s:+.1f}σ ({p:+.1f}%)" for k, (s, p) in o.sigmas.items())
    cl = f" closed {o.closed:.3f}" if math.isfinite(o.closed) else ""
    return (f"| {o.case} | {o.route[:90]} | {o.tool:.3f}{cl} | {o.linear:.3f} | {sig} | "
            f"{', '.join(o.added) or '-'} |")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", default=["a", "a+", "b", "b+", "c", "c+"])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--keep", type=Path, default=None, help="write the rigs' files here")
    ap.add_argument("--lib", type=Path, default=ROOT, help="the checkout whose CLI runs")
    a = ap.parse_args(argv)
    LIB[0] = a.lib.resolve()
    top = a.keep or Path(tempfile.mkdtemp(prefix="pmdcid_redteam_"))
    print("| case | route | held-out NRMSE tool | linear | parameters (error / stderr) | "
          "model effects |\n|---|---|---|---|---|---|")
    failures = []
    for name in a.cases:
        folder = top / name.replace("+", "_known")
        folder.mkdir(parents=True, exist_ok=True)
        o = run_case(case(name, a.seed), folder)
        print(fmt(o), flush=True)
        failures += [f"{name}: {f}" for f in o.failures]
    print("\nfailures:" if failures else "\nno failures")
    for f in failures:
        print("-", f)
    print(f"(files in {top})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
