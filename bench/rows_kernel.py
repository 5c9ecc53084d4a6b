"""Rows: the compiled kernel against the solve_ivp baseline, and how the kernel scales."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench.baseline import rms, simulate_baseline
from bench.table import Row
from bench.timing import Stats, interleaved, measure

KERNEL_TARGET_S = 5e-3
SPEEDUP_TARGET = 500.0


@dataclass
class Setup:
    """The reference case: the paper's model on a +-2 V, 40 s-period triangle at 1 kHz."""

    vals: dict[str, float]
    seconds: float = 120.0
    rate: float = 1000.0

    def input(self, factor: int = 1, seconds: float | None = None):
        from pmdcid.synth import triangle

        n = int(round((seconds or self.seconds * factor) * self.rate))
        t = np.arange(n) / self.rate
        return t, triangle(t, 2.0, 40.0)


def paper_setup() -> Setup:
    from pmdcid.simulate import neutral_values
    from pmdcid.synth import PAPER

    return Setup({**neutral_values(), **PAPER})


def _kernel_call(setup: Setup, factor: int = 1, buffered: bool = False):
    """(one run_kernel call, its internal steps); ``buffered``: into one reused output buffer,
    as a fit's simulations are (``run_kernel(out=)``)."""
    from pmdcid.simulate import param_vector
    from pmdcid.simulate.kernel import run_kernel
    from pmdcid.simulate.layout import NSTATE
    from pmdcid.simulate.substeps import choose_substeps

    t, u = setup.input(factor)
    dt = 1.0 / setup.rate
    p = param_vector(setup.vals)
    nsub = choose_substeps(dt, p)
    out = np.empty((len(u), NSTATE)) if buffered else None
    return (lambda: run_kernel(u, dt, p, out=out)), len(t) * nsub


def kernel_rows(setup: Setup, quick: bool) -> tuple[list[Row], Stats, Stats]:
    """Kernel time, ns per step, baseline time, ratio and RMS difference.

    Returns the rows, the kernel's Stats and the baseline's Stats (seconds per 120 s simulation)
    for the other rows' ratios.
    """
    from pmdcid.simulate import simulate_values

    run, steps = _kernel_call(setup)
    t, u = setup.input()
    # baseline: the full log unless quick (then a 10 s window, scaled per step)
    if quick:
        tb, ub = setup.input(seconds=10.0)
        how = "LSODA, 10 s window x12 per step"
    else:
        tb, ub = t, u
        how = "LSODA, rtol 1e-6, tanh-smoothed"
    scale = len(t) / len(tb)
    res: list = []
    # in turns: a batch of kernel runs, then one baseline run, so that both see the same load
    ks, bs = Stats(), Stats()
    run()
    for _ in range(3):
        ks.extend(measure(run, repeat=25, warmup=0, budget_s=2.0))
        bs.extend(measure(lambda: res.append(simulate_baseline(tb, ub, setup.vals)),
                          repeat=1, warmup=0).scaled(scale))
    base = res[-1]
    ksim = simulate_values(tb, ub, setup.vals)
    speedup = bs.median / ks.median
    ok_speed = speedup >= SPEEDUP_TARGET
    cpu_speedup = bs.cpu_median / ks.cpu_median
    rows = [
        Row(f"kernel: {setup.seconds:.0f} s triangle at 1 kHz, one simulation", ks, "s",
            f"{speedup:.0f}x faster than B1 (CPU: {cpu_speedup:.0f}x)", "<= 5 ms, >= 500x B1",
            ks.median <= KERNEL_TARGET_S and ok_speed,
            f"run_kernel incl. expm discretisation; {steps} internal steps"),
        Row("kernel: per internal step", ks.scaled(1e9 / steps), "ns"),
        Row(f"B1 baseline: solve_ivp {setup.seconds:.0f} s ({how})", bs, "s", "B1", "",
            None, f"{base.nfev} RHS calls; success={base.success}"),
        _rms_row(ksim, base),
    ]
    return rows, ks, bs


def _rms_row(ksim, base) -> Row:
    parts = []
    for name, unit in (("omega", "rad/s"), ("theta", "rad"), ("i", "A")):
        a, b = getattr(ksim, name), getattr(base, name)
        d = rms(a, b)
        parts.append(f"{name} {d:.2g} {unit} ({d / np.std(a):.1e} of std)")
    return Row("RMS difference kernel - B1", None, note="; ".join(parts))


def kernel_scaling_rows(setup: Setup, quick: bool) -> list[Row]:
    calls = {f: _kernel_call(setup, f, buffered=True) for f in (1, 4, 16)}
    got = interleaved({f: c[0] for f, c in calls.items()}, rounds=5 if quick else 15,
                      budget_s=5.0 if quick else 15.0)
    rows = []
    for factor in (1, 4, 16):
        s, steps = got[factor], calls[factor][1]
        ratio = s.median / got[1].median
        cpu = s.cpu_median / got[1].cpu_median if got[1].cpu_median else float("nan")
        rows.append(Row(f"scaling: kernel at {factor}x ({setup.seconds * factor:.0f} s)", s,
                        "s", f"{ratio:.2f}x the 1x time (CPU {cpu:.2f}x; linear: {factor}x)",
                        "<= 18x" if factor == 16 else "", ratio <= 18.0 if factor == 16 else None,
                        f"{s.median / steps * 1e9:.1f} ns per step; measured in turns; "
                        "one reused output buffer, as in a fit"))
    return rows


def hard_sign_row(b1: Stats, seconds: float = 20.0, timeout: float = 30.0) -> Row:
    """The paper's discontinuous model (hard sign()) in solve_ivp LSODA: chatters at zero speed.

    Run in a child process killed after ``timeout`` seconds (it can take many minutes).
    """
    import subprocess
    import sys
    import time
    from pathlib import Path

    script = Path(__file__).with_name("baseline.py")
    what = f"B0: solve_ivp LSODA, hard sign() friction, first {seconds:.0f} s of the log"
    t0 = time.perf_counter()
    try:
        out = subprocess.run([sys.executable, str(script), str(seconds)], capture_output=True,
                             text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        per_120 = b1.median * seconds / 120.0
        return Row(what, None, target="", note=f"did not finish in {timeout:.0f} s (killed); "
                   f"B1 (smoothed) does those {seconds:.0f} s in about {per_120:.2g} s")
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        return Row(what, None, note="failed: " + (out.stderr.strip().splitlines() or [""])[-1])
    sec, nfev, _ = out.stdout.split()
    return Row(what, Stats([float(sec)]), "s", f"{float(sec) / b1.median:.2g} B1", "",
               None, f"{nfev} RHS calls; child wall {wall:.1f} s")
