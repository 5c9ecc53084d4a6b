"""identify on step logs whose voltage is *measured* (noisy): does it take the clean logs' route?

``python -m bench.noisy_steps [--seeds 10] [--sigmas 0 0.3 1 1.5] [--rates 1000 500 100]``:
issue #24 item 7's logs (three free-running 4 s step logs, 0->6->0, 3->9->3, 0->12->0 V, the
level changing at 1 s and 2.5 s; the paper's motor with back-EMF ke = km; current 20 mA and
speed 0.2 rad/s of noise) with ``sigma_v`` of white noise on the logged voltage only, and a PWM
duty times a supply rippling 5 % (137 Hz and 3 Hz). Per case, over the seeds: identify ran
without error and wrote J; the logs sorted and the stages run as with the clean voltage (same
seed); the same steps (log, instant within a sample, from rest or moving) with amplitudes
within 4 standard errors (:func:`same`); J and bv within 2 of their stated standard errors of the
truth (per volt without the current column: J R/km, bv R/km + ke). ``identify --no-diagnose``
in memory, as the command runs it. ``--no-ripple`` leaves out the rippling supply's cases.
"""

from __future__ import annotations

import argparse
import math
import warnings
from dataclasses import dataclass

import numpy as np

from pmdcid.io import Log
from pmdcid.model import Model
from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.synth import PAPER

LEVELS = ((0.0, 6.0), (3.0, 9.0), (0.0, 12.0))
KE = PAPER["km"]


def logs(seed: int, sigma_v: float, rate: float, current: bool, ripple: float | None):
    """The three step logs (``ripple``: the supply's ripple frequency [Hz], or None)."""
    rng = np.random.default_rng(seed)
    vals = {**neutral_values(), **PAPER, "ke": KE}
    t = np.arange(0.0, 4.0, 1.0 / rate)
    out = []
    for low, high in LEVELS:
        v = np.where((t >= 1.0) & (t < 2.5), high, low)
        if ripple is not None:
            v = v * (1 + 0.05 * np.sin(2 * np.pi * ripple * t + rng.uniform(0, 2 * np.pi)))
        s = simulate_values(t, v, vals, False)
        cols = {"v": v + rng.normal(0.0, sigma_v, len(t)),
                "omega": s.omega + rng.normal(0.0, 0.2, len(t))}
        if current:
            cols["i"] = s.i + rng.normal(0.0, 0.02, len(t))
        out.append(Log(f"step{high:g}.csv", t, cols))
    return out


def truth(current: bool) -> tuple[float, float]:
    """(J, bv) as the model holds them: SI with the current, per volt without."""
    if current:
        return PAPER["J"], PAPER["bv"]
    r_km = PAPER["R"] / PAPER["km"]
    return PAPER["J"] * r_km, PAPER["bv"] * r_km + KE


@dataclass
class Run:
    ok: bool
    route: tuple = ()
    steps: tuple = ()
    amps: tuple = ()
    within: tuple = (False, False)


def run(seed, sigma_v, rate, current, ripple) -> Run:
    from pmdcid.pipeline import identify

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = identify(logs(seed, sigma_v, rate, current, ripple), Model(),
                           run_diagnose=False, progress=None)
    except Exception:  # noqa: BLE001 - a bench counts failures of any kind
        return Run(False)
    m = res.model
    if not m.has("J"):
        return Run(False)
    route = (tuple(p.kind for p in res.plan), tuple(name for name, _ in res.stages))
    mech = [r for name, r in res.stages if name.startswith("fit-mechanical")]
    steps = tuple((s.path, s.t0, s.from_rest, s.moved) for s in mech[0].steps) if mech else ()
    amps = tuple(s.amplitude for s in mech[0].steps) if mech else ()
    within = []
    for k, true in zip(("J", "bv"), truth(current), strict=True):
        p = m.parameters[k]
        within.append(p.stderr is not None and math.isfinite(p.stderr)
                      and abs(p.value - true) <= 2 * p.stderr)
    return Run(True, route, steps, amps, tuple(within))


def same(a: Run, ref: Run, sigma_v: float, rate: float) -> tuple[bool, bool]:
    """Same route; same steps (log, from rest or moving, the instant within a sample) with
    amplitudes within 4 standard errors of two plateau means (1 s or more each) plus 1 % of the
    range (a slow ripple's mean)."""
    if len(a.steps) != len(ref.steps):
        return a.route == ref.route, False
    tol = 4 * sigma_v * math.sqrt(2.0 / rate) + 0.01 * 12.0
    steps = all(x[0] == y[0] and x[2:] == y[2:] and abs(x[1] - y[1]) <= 1.5 / rate
                and abs(ax - ay) <= tol
                for x, y, ax, ay in zip(a.steps, ref.steps, a.amps, ref.amps, strict=True))
    return a.route == ref.route, steps


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0.0, 0.3, 1.0, 1.5])
    ap.add_argument("--rates", type=float, nargs="+", default=[1000.0, 500.0, 100.0])
    ap.add_argument("--no-ripple", action="store_true")
    args = ap.parse_args(argv)
    cases = [(s, r, c, None) for r in args.rates for c in (True, False) for s in args.sigmas]
    if not args.no_ripple:
        cases += [(s, 1000.0, True, f) for f in (137.0, 3.0) for s in (0.0, 0.3)]
    print("| sigma_v V | rate Hz | current | ripple | identify ok | same route | same steps "
          "| J within 2 se | bv within 2 se |")
    print("|---|---|---|---|---|---|---|---|---|")
    refs: dict = {}
    for sv, rate, cur, rip in cases:
        n = [0, 0, 0, 0, 0]
        for seed in range(1, args.seeds + 1):
            key = (seed, rate, cur)
            if key not in refs:
                refs[key] = run(seed, 0.0, rate, cur, None)
            a = run(seed, sv, rate, cur, rip)
            r, st = same(a, refs[key], sv, rate) if a.ok else (False, False)
            for k, hit in enumerate((a.ok, r, st, *a.within)):
                n[k] += bool(hit)
        print(f"| {sv:g} | {rate:g} | {'yes' if cur else 'no'} | "
              f"{'-' if rip is None else f'5 % at {rip:g} Hz'} | "
              + " | ".join(f"{k}/{args.seeds}" for k in n) + " |", flush=True)


if __name__ == "__main__":
    main()
