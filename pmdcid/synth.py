"""Synthetic logs: input profiles, sensor noise, and the bundled fixtures.

Used by ``pmdcid simulate`` (with noise options: :func:`simulated_columns`), ``make fixtures``
and the round-trip tests.
Noise comes from a ``numpy.random.Generator`` passed in (``default_rng(seed)``), never a
global seed.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io import write_log
from pmdcid.io.kinds import canonical, is_blocked
from pmdcid.model import Model
from pmdcid.simulate import (
    SimResult,
    blocked_rotor,
    input_is_torque,
    param_values,
    simulate_values,
)
from pmdcid.simulate.initial import initial_state, true_start

#: the paper's Table II parameters, km from its Table I (SI units)
PAPER = {"R": 2.3724, "L": 17.7933e-3, "km": 50.2e-3, "J": 3.10442e-3, "bv": 0.0314,
         "bc": 0.005, "dz": 6.35e-3}
GENERATOR = "pmdcid"


@dataclass(frozen=True)
class NoiseSpec:
    """Sensor noise: current std [A], speed std [rad/s], encoder counts per revolution (0 off)."""

    i: float = 0.0
    omega: float = 0.0
    encoder: int = 0


PAPER_NOISE = NoiseSpec(i=4e-3, omega=4e-3, encoder=4096)


def step(t: np.ndarray, amplitude: float, t0: float) -> np.ndarray:
    """Voltage step [V] of ``amplitude`` at ``t0`` [s]."""
    return np.where(t >= t0, amplitude, 0.0)


def triangle(t: np.ndarray, amplitude: float, period: float) -> np.ndarray:
    """Triangle [V] between -amplitude and +amplitude, starting at 0 and rising."""
    phase = (t / period + 0.25) % 1.0
    return amplitude * (4.0 * np.abs(phase - 0.5) - 1.0) * -1.0


def staircase(t: np.ndarray, amplitude: float, hold: float, rng: np.random.Generator) -> np.ndarray:
    """Random levels in [-amplitude, amplitude] held ``hold`` seconds each (held-out profile)."""
    n = int(np.ceil((t[-1] - t[0]) / hold)) + 1
    levels = rng.uniform(-amplitude, amplitude, n)
    levels[0] = 0.0
    return levels[np.minimum(((t - t[0]) / hold).astype(int), n - 1)]


def add_noise(sim: SimResult, noise: NoiseSpec, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Measured i, omega, theta from a simulation: Gaussian noise and encoder quantisation."""
    n = len(sim.t)
    out = {"i": sim.i + (rng.normal(0.0, noise.i, n) if noise.i > 0 else 0.0),
           "omega": sim.omega + (rng.normal(0.0, noise.omega, n) if noise.omega > 0 else 0.0),
           "theta": sim.theta.copy()}
    if noise.encoder > 0:
        q = 2 * np.pi / noise.encoder
        out["theta"] = np.round(out["theta"] / q) * q
    return out


def synth_log(t, u, vals: dict[str, float], noise: NoiseSpec, rng: np.random.Generator | None,
              torque_driven: bool = False, blocked: bool = False, nsub: int | None = None,
              x0=None, input_name: str | None = None, within: np.ndarray | None = None):
    """Simulate and add noise; returns (columns dict, SimResult). ``blocked`` holds the rotor;
    ``x0`` = (i, omega, theta) at ``t[0]`` (default rest); ``input_name`` names the input
    column (default ``tau`` or ``v``; a lumped model takes ``v`` through the torque path);
    ``within``: the input inside each sample (a loop-timed log's, as the fit stepped it)."""
    vals = blocked_rotor(vals) if blocked else dict(vals)
    if blocked:
        if x0 is not None:
            x0 = np.array([x0[0], 0.0, x0[2]], float)
    sim = simulate_values(t, u, vals, torque_driven, nsub, x0, within=within)
    meas = add_noise(sim, noise, rng) if rng is not None else {
        "i": sim.i, "omega": sim.omega, "theta": sim.theta}
    cols = {(input_name or ("tau" if torque_driven else "v")): np.asarray(u, float)}
    if not torque_driven:
        cols["i"] = meas["i"]
    if not blocked:
        cols["omega"] = meas["omega"]
        cols["theta"] = meas["theta"]
    return cols, sim


def closed_loop_log(log, vals: dict[str, float], spec, noise: NoiseSpec,
                    rng: np.random.Generator | None, torque_driven: bool, x0=None):
    """The closed loop of ``spec`` on ``log``'s reference (:mod:`pmdcid.simulate.closedloop`):
    columns as :func:`synth_log`'s with the input the simulated controller's output and the
    reference kept. The speed noise (when ``spec`` acts on the speed) is fed back through the
    controller, as a real loop feeds its sensor's noise back."""
    from pmdcid.simulate.closedloop import feedforward_of, reference_of, simulate_closed_loop

    ref = reference_of(log, spec)
    fb = None
    if rng is not None and noise.omega > 0 and spec.measured == "omega":
        fb = rng.normal(0.0, noise.omega, log.n)
    sim = simulate_closed_loop(log.t, vals, spec, ref, torque_driven, x0, logged_u=log.u,
                               noise=fb, feedforward=feedforward_of(log, spec),
                               logged_y=log[spec.measured] if log.has(spec.measured) else None)
    meas = {"i": sim.i, "omega": sim.omega, "theta": sim.theta}
    if rng is not None:
        extra = NoiseSpec(noise.i, 0.0 if fb is not None else noise.omega, noise.encoder)
        meas = add_noise(sim, extra, rng)
        if fb is not None:
            meas["omega"] = sim.omega  # its noise is in already, the loop saw it
    cols = {log.drive: sim.u, spec.reference: ref}
    if not torque_driven:
        cols["i"] = meas["i"]
    cols["omega"], cols["theta"] = meas["omega"], meas["theta"]
    return cols, sim


def simulated_columns(log, model: Model, noise: NoiseSpec = NoiseSpec(), seed: int | None = None,
                      blocked: bool = False, x0: dict[str, float] | str | None = None,
                      controller=None):
    """What ``pmdcid simulate`` writes for ``log``'s input: (t, columns, meta) -- the model's
    simulation with sensor noise from ``default_rng(seed)``, at the input's own instants.
    ``blocked`` (or a blocked-rotor log kind): the rotor held. ``controller`` (a
    :class:`~pmdcid.simulate.controller.ControllerSpec`): the closed loop from the log's
    reference, its input column the simulated controller's output."""
    torque = input_is_torque(log, model)
    vals = param_values(model, torque)
    rng = np.random.default_rng(seed)
    blocked = blocked or is_blocked(log.kind)  # a blocked-rotor profile: the rotor is held
    has_noise = noise.i > 0 or noise.omega > 0 or noise.encoder > 0
    with np.errstate(over="ignore", invalid="ignore"):
        if controller is not None:
            cols, _ = closed_loop_log(log, vals, controller, noise, rng if has_noise else None,
                                      torque, start_state(log, x0, vals))
        else:
            cols, _ = synth_log(log.t, log.u, vals, noise, rng if has_noise else None, torque,
                                blocked, x0=start_state(log, x0, vals), input_name=log.drive,
                                within=log.input_within())
    meta = {"generator": GENERATOR}
    if log.kind or blocked:  # the input's kind is the output's (io/kinds.py)
        meta["kind"] = "blocked-rotor" if blocked else canonical(log.kind)
    if has_noise:
        meta["noise"] = f"i={noise.i} A, omega={noise.omega} rad/s, encoder={noise.encoder}"
        meta["seed"] = str(seed)
    if controller is not None:
        meta["controller"] = controller.describe()
    t_out = log.t if log.t_file is None else log.t_file
    if log.resampled is not None:  # loop-timed INPUT: written at its own instants
        cols, t_out = log.resampled.at_file_instants(cols), log.resampled.t_file
    return t_out, cols, meta


def start_state(log, x0: dict[str, float] | str | None,
                vals: dict[str, float] | None = None) -> np.ndarray:
    """The state (i [A], omega [rad/s], theta [rad]) a simulation of ``log``'s input starts
    from: rest (None), given values (missing ones 0), or ``"measured"``: the state the log's
    first samples measured, read exactly as the fits and diagnose read it
    (:func:`pmdcid.simulate.initial.initial_state`: the first current and angle, the speed at
    the first sample, a start within noise of rest exactly at rest) and taken back through the
    model's sensor effects (``vals``: a speed sensor's bias), so that ``simulate --x0
    measured`` reproduces the errors the fits and diagnose report on the same log."""
    if x0 is None:
        return np.zeros(3)
    if isinstance(x0, str):
        if x0 != "measured":
            raise LogError(f"--x0 {x0!r}: give 'measured' or omega=VAL,i=VAL,theta=VAL")
        out = initial_state(log)
        if log.blocked:
            out[1] = 0.0
        return true_start(out, vals or {})
    return np.array([float(x0.get(n, 0.0)) for n in ("i", "omega", "theta")])


def paper_protocols(vals: dict[str, float], noise: NoiseSpec, rng: np.random.Generator,
                    amplitudes=(0.5, 1.0, 1.5, 2.0, 2.5)):
    """The paper's three protocols as (name, t, columns, meta) tuples.

    Blocked-rotor current steps (5 kHz, 0.3 s, onset 0.05 s), free-speed speed steps (1 kHz, 3 s,
    onset 0.5 s), and a +-2 V triangle (period 40 s, 120 s, 1 kHz).
    """
    out = []
    tb = np.arange(1500) / 5000.0
    for a in amplitudes:
        u = step(tb, a, 0.05)
        cols, _ = synth_log(tb, u, vals, noise, rng, blocked=True)
        out.append((f"blocked_{a:.1f}V", tb, cols, {"kind": "blocked-rotor", "amplitude_V": a}))
    ts = np.arange(3000) / 1000.0
    for a in amplitudes:
        u = step(ts, a, 0.5)
        cols, _ = synth_log(ts, u, vals, noise, rng)
        out.append((f"step_{a:.1f}V", ts, cols, {"kind": "free-speed-step", "amplitude_V": a}))
    tt = np.arange(120000) / 1000.0
    u = triangle(tt, 2.0, 40.0)
    cols, _ = synth_log(tt, u, vals, noise, rng)
    out.append(("triangle", tt, cols, {"kind": "triangle", "amplitude_V": 2.0, "period_s": 40.0}))
    return out


#: the fixture sets: folder -> (extra effects, their true parameters)
FIXTURE_SETS = {
    "paper": ([], {}),
    "hidden": (["stribeck"], {"fs": 3e-3, "ws": 0.15}),
}


def make_fixtures(folder: str | os.PathLike, seed: int = 20201) -> list[str]:
    """Write the bundled fixture logs (two sets) with their true parameters beside them."""
    from pmdcid.simulate import neutral_values

    root = Path(folder)
    written = []
    for k, (name, (effects, extra)) in enumerate(FIXTURE_SETS.items()):
        d = root / name
        d.mkdir(parents=True, exist_ok=True)
        vals = {**neutral_values(), **PAPER, **extra}
        rng = np.random.default_rng(seed + k)
        for fname, t, cols, meta in paper_protocols(vals, PAPER_NOISE, rng):
            meta = {"generator": GENERATOR, **meta, "seed": seed + k,
                    "noise": "i 4 mA, omega 4 mrad/s (std), theta 4096-count encoder"}
            write_log(d / f"{fname}.csv", t, cols, meta)
            written.append(str(d / f"{fname}.csv"))
        truth = {"parameters": {**PAPER, **extra}, "effects": effects,
                 "note": "true parameters the logs were simulated with (SI units); "
                         "km is the datasheet value (paper Table I)"}
        (d / "truth.json").write_text(json.dumps(truth, indent=2) + "\n")
    return written


def truth_model(values: dict[str, float], effects=()) -> Model:
    """A :class:`Model` holding true values (for tests and the demo)."""
    m = Model()
    for k, v in values.items():
        m.set(k, v, stage="truth")
    m.effects = list(effects)
    return m


if __name__ == "__main__":  # make fixtures
    import sys

    files = make_fixtures(sys.argv[1] if len(sys.argv) > 1 else "fixtures")
    print(f"wrote {len(files)} logs")
