"""The baseline pmdcid is measured against: scipy ``solve_ivp`` (LSODA) on the same model.

The way such a model is usually simulated outside Simulink: the paper's equations with the
discontinuities smoothed by tanh so that a variable-step solver can integrate them (a hard
``sign()`` makes LSODA chatter at zero speed and crawl). Same parameters, same zero-order-held
input, same output instants as the kernel; ``rtol`` 1e-6.

Smoothing (widths chosen small against the signals, so that the comparison is fair):

- Coulomb friction ``bc sign(omega)`` -> ``bc tanh(omega / eps_omega)`` [N m];
- hard dead zone on the magnetic torque Tm = km i [N m]: the gate ``|Tm| >= dz`` ->
  ``0.5 (1 + tanh((|Tm| - dz) / eps_torque))`` and ``sign(Tm)`` -> ``tanh(Tm / eps_torque)``.

The right-hand side uses plain Python floats and :mod:`math` (faster than numpy for scalars), so
the baseline is not made slow on purpose. Only the paper's model (R, L, km, J, bv, bc, dz and the
dead-zone slope/jump, plus back-EMF ke) is supported: that is what the comparison is about.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

#: default smoothing widths: speed [rad/s] and torque [N m]
EPS_OMEGA = 1e-3
EPS_TORQUE = 1e-5


@dataclass
class BaselineResult:
    """Baseline states at the requested instants: t [s], i [A], omega [rad/s], theta [rad]."""

    t: np.ndarray
    i: np.ndarray
    omega: np.ndarray
    theta: np.ndarray
    nfev: int
    success: bool
    message: str


def _hard_sign(x: float) -> float:
    return 1.0 if x > 0.0 else (-1.0 if x < 0.0 else 0.0)


def make_rhs(u: np.ndarray, dt: float, vals: dict[str, float], eps_omega: float = EPS_OMEGA,
             eps_torque: float = EPS_TORQUE, smooth: bool = True):
    """Right-hand side f(t, x) of x = (i, omega, theta) with u zero-order held at ``dt`` [s].

    ``smooth=False`` gives the paper's discontinuous model (hard ``sign()`` friction and dead
    zone, as in a Simulink ``sign`` block), which a variable-step solver handles very badly.
    """
    R, L, km, J = (float(vals[k]) for k in ("R", "L", "km", "J"))
    bv, bc, dz = (float(vals.get(k, 0.0)) for k in ("bv", "bc", "dz"))
    ke = float(vals.get("ke", 0.0))
    kbar = float(vals.get("dz_slope", 1.0))
    khat = float(vals.get("dz_offset", 0.0))
    uu = [float(x) for x in u]
    n = len(uu)
    tanh = math.tanh
    sign = _hard_sign

    def rhs(t, x):
        k = int(t / dt)
        v = uu[k if k < n else n - 1]
        i, w = float(x[0]), float(x[1])
        tm = km * i
        gate = 0.5 * (1.0 + tanh((abs(tm) - dz) / eps_torque)) if dz > 0.0 else 1.0
        td = gate * (kbar * tm + khat * tanh(tm / eps_torque))
        di = (v - R * i - ke * w) / L
        dw = (td - bv * w - bc * tanh(w / eps_omega)) / J
        return [di, dw, w]

    def rhs_hard(t, x):
        k = int(t / dt)
        v = uu[k if k < n else n - 1]
        i, w = float(x[0]), float(x[1])
        tm = km * i
        td = kbar * tm + khat * sign(tm) if abs(tm) >= dz else 0.0
        di = (v - R * i - ke * w) / L
        dw = (td - bv * w - bc * sign(w)) / J
        return [di, dw, w]

    return rhs if smooth else rhs_hard


def simulate_baseline(t: np.ndarray, u: np.ndarray, vals: dict[str, float],
                      rtol: float = 1e-6, atol: float = 1e-9, method: str = "LSODA",
                      eps_omega: float = EPS_OMEGA,
                      eps_torque: float = EPS_TORQUE, smooth: bool = True) -> BaselineResult:
    """Simulate from rest on the uniform grid ``t`` [s] under ``u`` [V] with ``solve_ivp``."""
    t = np.asarray(t, dtype=float)
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    rhs = make_rhs(u, dt, vals, eps_omega, eps_torque, smooth)
    sol = solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0, 0.0], method=method, t_eval=t,
                    rtol=rtol, atol=atol)
    y = sol.y
    if y.shape[1] != len(t):  # solver stopped early: pad so callers see the failure in the RMS
        pad = np.full((3, len(t) - y.shape[1]), np.nan)
        y = np.hstack([y, pad])
    return BaselineResult(t, y[0], y[1], y[2], int(sol.nfev), bool(sol.success), sol.message)


def rms(a: np.ndarray, b: np.ndarray) -> float:
    """Root-mean-square difference of two equal-length signals (same unit)."""
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


if __name__ == "__main__":  # the hard-sign() run, in a child the benchmark can kill
    import sys
    import time

    from pmdcid.simulate import neutral_values
    from pmdcid.synth import PAPER, triangle

    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 20.0
    tt = np.arange(int(round(seconds * 1000))) / 1000.0
    t0 = time.perf_counter()
    res = simulate_baseline(tt, triangle(tt, 2.0, 40.0), {**neutral_values(), **PAPER},
                            smooth=False)
    print(f"{time.perf_counter() - t0:.3f} {res.nfev} {res.success}")
