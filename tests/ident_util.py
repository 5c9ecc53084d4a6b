"""Shared helpers of the identification round-trip tests: perturbed truths and synthetic logs."""

from __future__ import annotations

import numpy as np

from pmdcid.identify.electrical import fit_electrical
from pmdcid.identify.mechanical import fit_mechanical
from pmdcid.identify.nonlinear import fit_nonlinear
from pmdcid.io import Log
from pmdcid.model import Model
from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.synth import PAPER, PAPER_NOISE, NoiseSpec, step, synth_log, triangle

AMPLITUDES = (0.5, 1.0, 1.5, 2.0, 2.5)
MOVED = ("R", "L", "J", "bv", "bc", "dz")
#: a motor in per-volt units (J R/km, bv R/km + ke, friction R/km): the paper's motor with
#: back-EMF, R = 2.37 ohm, km = ke = 50.2e-3
G = PAPER["km"] / PAPER["R"]
LUMPED = {"J": PAPER["J"] / G, "bv": PAPER["bv"] / G + PAPER["km"], "bc": PAPER["bc"] / G,
          "dz": 1.5 * PAPER["dz"] / G}


def perturbed_truth(rng: np.random.Generator, spread: float = 0.25, **extra) -> dict:
    """Table II values (km from Table I) each moved by a uniform factor in 1 +- spread."""
    vals = {**neutral_values(), **PAPER, **extra}
    for k in MOVED:
        vals[k] = PAPER[k] * rng.uniform(1 - spread, 1 + spread)
    return vals


def as_log(name: str, t: np.ndarray, cols: dict, kind: str = "") -> Log:
    return Log(path=name, t=np.asarray(t, float), data={k: np.asarray(v, float)
                                                        for k, v in cols.items()},
               meta={"kind": kind} if kind else {})


def blocked_logs(vals, rng, amplitudes=AMPLITUDES, noise=PAPER_NOISE, rate=5000.0,
                 seconds=0.3, onset=0.05):
    t = np.arange(int(seconds * rate)) / rate
    out = []
    for a in amplitudes:
        cols, _ = synth_log(t, step(t, a, onset), vals, noise, rng, blocked=True)
        out.append(as_log(f"blocked_{a}V", t, cols, "blocked-rotor"))
    return out


def step_logs(vals, rng, amplitudes=AMPLITUDES, noise=PAPER_NOISE, seconds=3.0, onset=0.5):
    t = np.arange(int(seconds * 1000)) / 1000.0
    out = []
    for a in amplitudes:
        cols, _ = synth_log(t, step(t, a, onset), vals, noise, rng)
        out.append(as_log(f"step_{a}V", t, cols, "free-speed-step"))
    return out


def triangle_log(vals, rng, periods=2, period=20.0, amplitude=2.0, noise=PAPER_NOISE):
    t = np.arange(int(periods * period * 1000)) / 1000.0
    cols, _ = synth_log(t, triangle(t, amplitude, period), vals, noise, rng)
    return as_log("triangle", t, cols, "triangle")


def triangle_fit_problem(seed: int = 1616):
    """A short noisy triangle and a model 15 % off in J, bv, bc, dz: (truth, log, model, free),
    the problem the solver's own tests fit (fdjac, tall)."""
    from pmdcid.model import Model

    rng = np.random.default_rng(seed)
    truth = perturbed_truth(rng)
    log = triangle_log(truth, rng, periods=1, period=10.0)
    free = ["J", "bv", "bc", "dz"]
    model = Model()
    for k in ("R", "L", "km", *free):
        model.set(k, truth[k] * (1.15 if k in free else 1.0), stage="start")
    return truth, log, model, free


def slow_triangle(step: int, held: bool, seed: int):
    """The paper's motor under its 40 s triangle, logged every ``step`` ms: the input generated
    at 1 kHz (a continuous ramp as far as a slow log can tell) or, ``held``, simulated from the
    slow samples themselves (a drive that holds each logged value: the contract's reading)."""
    from pmdcid.model import Model
    from pmdcid.simulate import simulate_values

    vals = {**neutral_values(), **PAPER}
    rng = np.random.default_rng(seed)
    tf = np.arange(120_000) / 1000.0
    u = triangle(tf, 2.0, 40.0)
    t, us = tf[::step], u[::step]
    sim = simulate_values(t, us, vals) if held else simulate_values(tf, u, vals)
    idx = slice(None) if held else slice(None, None, step)
    n = len(t)
    cols = {"v": us, "i": sim.i[idx] + rng.normal(0, 4e-3, n),
            "omega": sim.omega[idx] + rng.normal(0, 4e-3, n)}
    m = Model()
    for k in ("R", "L", "km", "J", "bv", "bc", "dz"):
        m.set(k, vals[k] * (1.1 if k in ("J", "bv", "bc") else 1.0))
    return as_log("ramp.csv", t, cols), m, vals


def extreme_numbers(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) numbers across 600 decades, with negative zeros and small integers mixed in: what
    the CSV readers' agreement tests write in many formats."""
    x = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-300, 300, (n, 3))
    x[::7, 1] = -0.0
    x[::11, 2] = rng.integers(-5, 5, len(x[::11, 2]))
    return x


def paper_stages(truth: dict, rng: np.random.Generator):
    """The paper's three stages on fresh noisy logs; returns (all logs, fitted model)."""
    logs = [*blocked_logs(truth, rng), *step_logs(truth, rng), triangle_log(truth, rng)]
    model = Model()
    model.set("km", truth["km"], stage="datasheet")
    fit_electrical(logs[:5], model).apply(model)
    fit_mechanical(logs[5:10], model).apply(model)
    fit_nonlinear([logs[10]], model).apply(model)
    return logs, model


#: a small lab motor with back-EMF (the rig of docs/identification.md, "A joint fit stopped on
#: the staircase"): at 2 kHz its mechanical time constant over 50 (0.84 ms) exceeds the sample
#: period, so the fit's kernel takes one internal step a sample and every stick and breakaway
#: moves by whole samples with J and bv: the cost is a staircase in them too
SMALL_MOTOR = {"R": 3.2, "L": 4e-3, "km": 0.03, "ke": 0.03, "J": 1.2e-5, "bv": 6e-6,
               "bc": 2.5e-3, "dz": 4e-3}


def small_motor_logs(vals, rng, rate=2000.0, hold=0.3):
    """Steps from rest, steps from the 8 V steady state (turning at the first sample) and a
    10 V triangle of 4 s, current and speed logged (4 mA, 0.3 rad/s of noise); simulated with
    32 internal steps a sample, so that the truth is no point of the fit's own staircase."""
    noise = NoiseSpec(i=4e-3, omega=0.3)
    w = (vals["km"] * 8 / vals["R"] - vals["bc"]) / (
        vals["bv"] + vals["km"] * vals["ke"] / vals["R"])
    runs = (("steps", np.repeat([0.0, 3, 6, 9, 4, 0, -5, -10, -2, 0], int(hold * rate)), None),
            ("steps_turning", np.repeat([8.0, 3, 11, 5, -6, 0], int(hold * rate)),
             ((8 - vals["ke"] * w) / vals["R"], w, 0.0)),
            ("triangle", triangle(np.arange(int(4 * rate)) / rate, 10.0, 4.0), None))
    out = []
    for name, v, x0 in runs:
        t = np.arange(len(v)) / rate
        cols, _ = synth_log(t, v, vals, noise, rng, nsub=32, x0=x0)
        out.append(as_log(name, t, cols))
    return out


#: a motor of bench/lumped_coverage.py's family (its seed 7): L/R 3.6 ms, back-EMF 90 % of the
#: damping, the dead zone 21 % above the Coulomb friction
SLOW = {**neutral_values(), "R": 2.0, "L": 7.589e-3, "km": 0.021, "ke": 0.021, "J": 1.305e-5,
        "bv": 2.45e-5, "bc": 2.804e-3, "dz": 3.393e-3}


def logged_at_100_hz(seed: int):
    """(per-volt truth, four voltage steps of 1.5 s and an 8 s +-8 V triangle of SLOW, voltage
    and speed at 100 Hz, noise 0.3 % of the speed's range): bench/lumped_coverage.py's logs at a
    rate common on real rigs, whose steps leave L/R open."""
    rng = np.random.default_rng(seed)
    t, tt = np.arange(150) / 100.0, np.arange(800) / 100.0
    runs = [(f"step_{a:g}V", t, step(t, a, 0.2)) for a in (2.0, 4.0, 6.0, 8.0)]
    runs.append(("triangle", tt, triangle(tt, 8.0, 4.0)))
    sims = [(n, t_, u, simulate_values(t_, u, SLOW, nsub=64).omega) for n, t_, u in runs]
    sigma = 0.003 * max(float(np.ptp(w)) for *_, w in sims)
    logs = [as_log(n, t_, {"v": u, "omega": w + rng.normal(0, sigma, w.size)})
            for n, t_, u, w in sims]
    g = SLOW["R"] / SLOW["km"]
    truth = {"J": SLOW["J"] * g, "bv": SLOW["bv"] * g + SLOW["ke"], "bc": SLOW["bc"] * g,
             "dz": SLOW["dz"] * g}
    return truth, logs
