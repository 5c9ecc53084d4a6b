"""pmdcid plan on the paper's motor: Monte Carlo against the prediction, and the paper's protocol.

Run from the repository root (a few minutes on 2 cores: 20 fits of two minutes of data):

    python docs/examples/plan_montecarlo.py [--budget 120] [--seeds 20]

1. Plans for the paper's motor (fixtures/paper/truth.json values, pmdcid.synth.PAPER) within
   +-2.5 V, the paper fixtures' sensor noise (speed 4 mrad/s, current 4 mA), ``--budget`` s.
2. Records the plan ``--seeds`` times in simulation (noise from default_rng(seed)), fits R, L
   from the currents then J, bv, bc, dz from the speeds by simulation error each time
   (pmdcid.plan.montecarlo) and prints each parameter's realised RMS error and standard
   deviation beside the predicted standard error.
3. Computes the paper's protocol (five blocked-rotor steps, five speed steps 0.5..2.5 V, a 120 s
   +-2 V triangle: 136.5 s) and a plan of the same 136.5 s with the same Fisher machinery.
4. Writes docs/plan_montecarlo.png (estimates against the predicted +-1 and +-2 standard errors)
   and docs/plan_profiles.png (the 136.5 s plan's inputs and predicted speed).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from pmdcid.plan import fisher as fi
from pmdcid.plan.design import Settings, plan_for_model
from pmdcid.plan.montecarlo import monte_carlo
from pmdcid.plan.paper_protocol import paper_profiles, protocol_seconds, protocol_stderr
from pmdcid.synth import PAPER, truth_model

MECH = ("J", "bv", "bc", "dz")
NOISE = {"noise_omega": 4e-3, "noise_i": 4e-3}
DOCS = Path(__file__).resolve().parents[1]


def monte_carlo_table(budget: float, seeds: int):
    model = truth_model(PAPER)
    plan = plan_for_model(model, Settings(umax=2.5, budget=budget, effects=False, **NOISE))
    print(f"plan for {budget:g} s: " + ", ".join(f"{p.kind} {p.seconds:.1f} s"
                                                 for p in plan.profiles))
    t0 = time.perf_counter()
    est = monte_carlo(plan, model, range(seeds))
    print(f"{seeds} simulated recordings fitted in {time.perf_counter() - t0:.0f} s\n")
    print(f"{'param':<6} {'predicted':>10} {'RMS error':>10} {'std dev':>10} {'RMS/pred':>9}")
    z = {}
    for n in plan.names:
        se = plan.stderr[n]
        err = est[n] - PAPER[n]
        rms = float(np.sqrt(np.mean(err**2)))
        z[n] = err / se
        print(f"{n:<6} {se:10.3g} {rms:10.3g} {np.std(est[n], ddof=1):10.3g} {rms / se:9.2f}")
    pooled = float(np.sqrt(np.mean(np.concatenate(list(z.values())) ** 2)))
    print(f"pooled RMS error / predicted: {pooled:.2f}\n")
    return plan, z


def paper_comparison():
    model = truth_model(PAPER)
    prof = paper_profiles()
    seconds = protocol_seconds(prof)
    paper = protocol_stderr(model, prof, {"omega": 4e-3, "i": 4e-3})
    plan = plan_for_model(model, Settings(umax=2.5, budget=seconds, effects=False, **NOISE))
    print(f"same {seconds:g} s, relative standard errors (x 1e-4):")
    print(f"{'param':<6} {'paper':>8} {'plan':>8} {'ratio':>7}")
    for n in plan.names:
        a, b = paper[n] / PAPER[n], plan.stderr[n] / PAPER[n]
        print(f"{n:<6} {1e4 * a:8.3f} {1e4 * b:8.3f} {a / b:7.2f}")
    wp = max(paper[n] / PAPER[n] for n in MECH)
    wq = max(plan.stderr[n] / PAPER[n] for n in MECH)
    print(f"worst among J, bv, bc, dz: paper {1e4 * wp:.3f}e-4, plan {1e4 * wq:.3f}e-4, "
          f"{wp / wq:.2f}x smaller")
    print("plan: " + ", ".join(f"{p.kind} {p.seconds:.1f} s" for p in plan.profiles))
    return plan


def figure_montecarlo(z, path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 3.2))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(111)
    names = list(z)
    for k, n in enumerate(names):
        ax.plot(np.full(len(z[n]), k) + np.linspace(-0.15, 0.15, len(z[n])), z[n], "o", ms=4)
    for s, style in ((1, "--"), (2, ":")):
        ax.axhline(s, color="grey", ls=style)
        ax.axhline(-s, color="grey", ls=style)
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("(estimate - truth) / predicted stderr")
    ax.set_title("Monte Carlo fits of the plan against its predicted standard errors")
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def figure_profiles(plan, path):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    model = truth_model(PAPER)
    vals = fi.model_values(model, plan.drive)
    free = [p for p in plan.profiles if not p.blocked]
    fig = Figure(figsize=(8, 2.2 * len(free)))
    FigureCanvasAgg(fig)
    for k, p in enumerate(free):
        ax = fig.add_subplot(len(free), 1, k + 1)
        sim = fi.simulate_profile(p.t, p.u, vals, plan.drive, False)
        ax.plot(p.t, p.u, lw=0.8, label="v [V]")
        ax.plot(p.t, sim.omega, lw=0.8, label="omega [rad/s]")
        ax.set_title(f"{p.name}.csv: {p.kind}, {p.seconds:.1f} s", fontsize=9)
        ax.set_xlim(0, min(p.seconds, 20.0))
        ax.legend(loc="upper right", fontsize=7)
    ax.set_xlabel("t [s] (first 20 s of each)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--budget", type=float, default=120.0)
    ap.add_argument("--seeds", type=int, default=20)
    a = ap.parse_args()
    _, z = monte_carlo_table(a.budget, a.seeds)
    figure_montecarlo(z, DOCS / "plan_montecarlo.png")
    plan = paper_comparison()
    figure_profiles(plan, DOCS / "plan_profiles.png")
    print(f"wrote {DOCS / 'plan_montecarlo.png'} and {DOCS / 'plan_profiles.png'}")


if __name__ == "__main__":
    main()
