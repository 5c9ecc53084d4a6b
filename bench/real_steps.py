"""fit-mechanical's per-step numbers on the real rigs in ../shared/data/real (read only).

``.venv/bin/python -m bench.real_steps``: per rig and voltage level, Kmot (steady speed per volt)
and tau_mot (first order) as mean ± repeat-to-repeat std, the dead time, and the steady-speed line
(slope rad/s per V, offset V) over every plateau. km = 1 (Kmot and tau do not depend on it); R, L
the bench values of the rigs' READMEs where given (they enter only tau_m and T_break).
"""

from __future__ import annotations

import glob
from collections import defaultdict
from pathlib import Path

import numpy as np

from pmdcid.identify.mechanical import fit_mechanical, steady_line
from pmdcid.io import read_log
from pmdcid.model import Model

REAL = Path(__file__).resolve().parents[2] / "shared" / "data" / "real"
#: rig folder -> (R [ohm], L [H]): the READMEs' bench values; guanlunlu has none (placeholder)
RIGS = {"fra233-g04": (3.40, 2.85e-3), "fra233-2025-pboon": (3.18, 2.84e-3),
        "guanlunlu-l298n": (3.0, 3e-3)}


def rig_steps(rig: str, pattern: str = "step_*.csv"):
    """fit-mechanical on every matching log of ``rig`` at once; returns the result."""
    R, L = RIGS[rig]
    m = Model()
    m.set("R", R)
    m.set("L", L)
    files = sorted(glob.glob(str(REAL / rig / pattern)))
    return fit_mechanical([read_log(f) for f in files], m, km=1.0)


def _sd(x):
    return float(np.std(x, ddof=1)) if len(x) > 1 else float("nan")


def summary(res) -> list[str]:
    by = defaultdict(list)
    moved = [s for s in res.steps if s.moved]
    for s in moved:
        by[round(s.level, 2)].append((s.kmot, s.tau_mot, s.dead_time))
    out = []
    for lev, rows in sorted(by.items()):
        a = np.array(rows)
        k, t = a[:, 0], 1e3 * a[:, 1]
        out.append(f"  {lev:6.4g} V  n={len(a)}  Kmot {k.mean():8.4g} ± {_sd(k):.2g} rad/s/V "
                   f"({100 * _sd(k) / k.mean():.2g} %)  tau_mot {t.mean():6.4g} ± {_sd(t):.2g} "
                   f"ms ({100 * _sd(t) / t.mean():.2g} %)  dead {1e3 * a[:, 2].mean():.3g} ms")
    if len(by) >= 2:
        a, c, cov = steady_line(np.array([s.level for s in moved]),
                                np.array([s.omega_ss for s in moved]),
                                np.array([s.omega_ss_se for s in moved]))
        out.append(f"  line: {a:.4g} ± {np.sqrt(cov[0, 0]):.2g} rad/s per V, offset "
                   f"{-c / a:.3g} V")
    return out


def main() -> None:
    if not REAL.is_dir():
        print(f"{REAL} is absent: nothing to measure")
        return
    for rig in RIGS:
        for pattern in ("step_*.csv", "stair_*.csv"):
            if not list((REAL / rig).glob(pattern)):
                continue
            res = rig_steps(rig, pattern)
            print(f"{rig} {pattern}: {sum(s.moved for s in res.steps)} of {len(res.steps)} "
                  "steps used")
            print("\n".join(summary(res)))


if __name__ == "__main__":
    main()
