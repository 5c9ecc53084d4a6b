"""The one simulation kernel: exact piecewise-linear stepping with true stick-slip, compiled.

State x = (i [A], omega [rad/s], theta [rad]). Between events the model is linear with constant
forcing, so each internal step of length h uses the exact discretisation
``x+ = Phi x + Gamma f`` (matrix exponential of the augmented system, compiled), computed once
per call for the two dead-zone modes. Input is zero-order held over each sample period.
Non-linear terms (Coulomb sign, Stribeck, quadratic drag, cogging, brush drop, the dead-zone jump)
are evaluated at the start of each internal step and held over it; a rotor at rest stays exactly
at rest while the torque on it is within the static friction level (no tanh smoothing), and a
rotor whose speed would cross zero is stopped there and re-tested for sticking.

With bc = dz = 0 and no effects the kernel is exact to rounding for any step; with them it
converges at first order in h at the events.
"""

from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from pmdcid.errors import ModelError
from pmdcid.simulate import aot
from pmdcid.simulate.layout import BC, BV, DZ_OFFSET, DZ_SLOPE, FS, KE, KM, J, L, R
from pmdcid.simulate.lazyjit import njit
from pmdcid.simulate.terms import (
    armature_voltage,
    dead_zone,
    dead_zone_engaged,
    drive_voltage,
    load_torque,
    sgn,
    sliding_friction,
    static_friction,
)


def system_matrix(p: np.ndarray, engaged: bool, torque_driven: bool) -> np.ndarray:
    """Continuous-time A (3x3) of x = (i, omega, theta) in one dead-zone mode.

    Voltage-driven: L di/dt = v - R i - ke omega; J domega/dt = k*km*i - bv omega + ...
    Torque-driven: the current row is zero (the current is not simulated).
    """
    A = np.zeros((3, 3))
    if not torque_driven:
        A[0, 0] = -p[R] / p[L]
        A[0, 1] = -p[KE] / p[L]
        if engaged:
            A[1, 0] = p[DZ_SLOPE] * p[KM] / p[J]
    A[1, 1] = -p[BV] / p[J]
    A[2, 1] = 1.0
    return A


@njit(cache=True)
def expm_small(M):  # pragma: no cover - compiled
    """Matrix exponential of a small dense matrix: scaling and squaring of a Taylor series.

    Scaled to norm <= 1/2 and summed to 20 terms (truncation < 1e-25 relative), then squared
    back. Used instead of ``scipy.linalg.expm`` because for 6x6 matrices the BLAS thread pool
    makes scipy's call cost milliseconds; this costs about a microsecond.
    """
    n = M.shape[0]
    norm = 0.0
    for r in range(n):
        row = 0.0
        for c in range(n):
            row += abs(M[r, c])
        norm = max(norm, row)
    s = 0
    if norm > 0.5:
        s = int(math.ceil(math.log2(norm / 0.5)))
    A = M / (2.0**s)
    E = np.eye(n)
    term = np.eye(n)
    for k in range(1, 21):
        term = _matmul(term, A) / k
        E = E + term
    for _ in range(s):
        E = _matmul(E, E)
    return E


@njit(cache=True)
def _matmul(X, Y):  # pragma: no cover - compiled; plain loops, no BLAS call for tiny matrices
    n, m, q = X.shape[0], X.shape[1], Y.shape[1]
    Z = np.zeros((n, q))
    for r in range(n):
        for k in range(m):
            x = X[r, k]
            for c in range(q):
                Z[r, c] += x * Y[k, c]
    return Z


def discretize(p: np.ndarray, h: float, torque_driven: bool) -> tuple[np.ndarray, np.ndarray]:
    """Exact zero-order-hold discretisation for both modes: Phi (2,3,3) and Gamma (2,3,3).

    ``Phi = expm(A h)``, ``Gamma = int_0^h expm(A s) ds`` (from the augmented 6x6 exponential).
    Mode 0 is the dead zone engaged (torque passes), mode 1 disengaged.
    """
    Phi = np.empty((2, 3, 3))
    Gam = np.empty((2, 3, 3))
    for m, engaged in enumerate((True, False)):
        M = np.zeros((6, 6))
        M[:3, :3] = system_matrix(p, engaged, torque_driven)
        M[:3, 3:] = np.eye(3)
        E = _compiled("expm_small")(M * h)
        Phi[m] = E[:3, :3]
        Gam[m] = E[:3, 3:]
    return Phi, Gam


@njit(cache=True)
def _run(u, p, Phi, Gam, nsub, torque_driven, x0):  # pragma: no cover - compiled
    n = u.shape[0]
    out = np.empty((n, 3))
    i = x0[0]
    w = x0[1]
    th = x0[2]
    Lh = p[L]
    Jm = p[J]
    a_stuck = Phi[1, 0, 0]  # current decay over h with omega = 0 (disengaged row has no coupling)
    g_stuck = Gam[1, 0, 0]
    fstat = static_friction(p)
    clamp = fstat > 0.0
    for k in range(n):
        out[k, 0] = i
        out[k, 1] = w
        out[k, 2] = th
        if torque_driven:
            tin = u[k]
            vin = 0.0
        else:
            vin = drive_voltage(p, u[k])
            tin = 0.0
        for _ in range(nsub):
            if torque_driven:
                tm = tin
            else:
                tm = p[KM] * i
            eng = dead_zone_engaged(p, tm)
            td = dead_zone(p, tm)
            tl = load_torque(p, th)
            tentative = False
            i_stuck = i
            if w == 0.0:
                net = td - tl
                if abs(net) <= fstat:
                    # at rest: the current moves with omega = 0; if the torque it builds breaks
                    # the rotor free within this step, try a moving step (accepted only if the
                    # rotor then moves in the driving direction: second-order breakaway timing)
                    if not torque_driven:
                        ve = armature_voltage(p, vin, 0.0)
                        i_stuck = a_stuck * i + g_stuck * ve / Lh
                        net = dead_zone(p, p[KM] * i_stuck) - tl
                    if abs(net) <= fstat:
                        i = i_stuck
                        continue
                    tentative = True
                direction = sgn(net)
            else:
                direction = sgn(w)
            # forcing: electrical row (V/H) and mechanical row (N m / kg m^2)
            if torque_driven:
                fe = 0.0
                fm = (td - tl - sliding_friction(p, w, direction)) / Jm
                m = 0
            else:
                fe = armature_voltage(p, vin, w) / Lh
                if eng:
                    m = 0
                    fm = p[DZ_OFFSET] * sgn(i)
                else:
                    m = 1
                    fm = 0.0
                fm = (fm - tl - sliding_friction(p, w, direction)) / Jm
            i1 = Phi[m, 0, 0] * i + Phi[m, 0, 1] * w + Gam[m, 0, 0] * fe + Gam[m, 0, 1] * fm
            w1 = (Phi[m, 1, 0] * i + Phi[m, 1, 1] * w + Gam[m, 1, 0] * fe
                  + Gam[m, 1, 1] * fm)
            th1 = (th + Phi[m, 2, 0] * i + Phi[m, 2, 1] * w + Gam[m, 2, 0] * fe
                   + Gam[m, 2, 1] * fm)
            if tentative and w1 * direction <= 0.0:
                i = i_stuck  # did not break free after all: stays at rest
                continue
            if clamp and w1 * direction < 0.0:
                w1 = 0.0  # the speed would cross zero: stop here, re-test sticking next step
            if torque_driven:
                i1 = 0.0
            i = i1
            w = w1
            th = th1
    return out


#: internal steps per mechanical time constant. The linear dynamics are exact at any step (the
#: matrix exponential), but a stop or a breakaway is placed to within one internal step, an
#: error of about h / tau of the transient (2 %): measured on a fast motor (tau = 10 ms), the
#: speed's RMS error against a 200-substep reference halves with each halving of h
STEPS_PER_TAU = 50.0
#: most internal steps (samples x substeps) one simulation may take: minutes of compute. Past it
#: the input is wrong (J = 1e-12, time in microseconds, a 1e300 s sample period), not the motor
MAX_STEPS = 5e8


class WorkBoundError(ModelError):
    """A simulation would take more than :data:`MAX_STEPS` internal steps (message says why)."""


@contextmanager
def bounded_for(model_path):
    """Name ``model_path`` in a :class:`WorkBoundError` raised inside the block."""
    try:
        yield
    except WorkBoundError as exc:
        if exc.path is not None or model_path is None:
            raise
        raise WorkBoundError(str(exc), str(model_path)) from None


def choose_substeps(dt: float, p: np.ndarray, h_max: float | None = None) -> int:
    """Internal steps per sample: h <= min(1 ms, tau_mech / 50) unless ``h_max`` [s] is given;
    tau_mech = J / (bv + km ke / R) [s], the back-EMF's damping included."""
    if h_max is None:
        h_max = 1e-3
        damping = p[BV] + (p[KM] * p[KE] / p[R] if p[R] > 0 else 0.0)
        if damping > 0 and p[J] > 0:
            h_max = min(h_max, p[J] / damping / STEPS_PER_TAU)
    return max(1, int(math.ceil(dt / h_max - 1e-9)))


def check_work(n: int, dt: float, nsub: int, p: np.ndarray) -> None:
    """Raise :class:`WorkBoundError` when ``n`` samples of ``nsub`` substeps exceed the bound."""
    steps = float(n) * float(nsub)
    if steps <= MAX_STEPS:
        return
    damping = p[BV] + (p[KM] * p[KE] / p[R] if p[R] > 0 else 0.0)
    tau = p[J] / damping if damping > 0 else math.inf
    raise WorkBoundError(
        f"the simulation would take {steps:.2g} internal steps ({n} samples x {float(nsub):.2g} "
        f"substeps; limit {MAX_STEPS:.0e}): a sample period of {dt:.3g} s is "
        f"{dt / tau:.2g} x the time constant J/(bv+km^2/R) = {tau:.3g} s: check J (value, unit) "
        "or the time unit (t in ms or us? -c t=COLUMN*ms)")


def run_kernel(u: np.ndarray, dt: float, p: np.ndarray, torque_driven: bool = False,
               nsub: int | None = None, x0=None) -> np.ndarray:
    """Simulate from ``x0`` (default rest) under the zero-order-held input ``u`` sampled at ``dt``.

    Returns an (n, 3) array of (i [A], omega [rad/s], theta [rad]) at the sample instants; row k
    is the state at t_k, before input u[k] is applied over [t_k, t_k + dt).
    """
    if nsub is None:
        nsub = choose_substeps(dt, p)
    check_work(len(u), dt, nsub, p)
    h = dt / nsub
    Phi, Gam = discretize(p, h, torque_driven)
    return run_discretized(u, p, Phi, Gam, nsub, torque_driven, x0)


def run_discretized(u: np.ndarray, p: np.ndarray, Phi: np.ndarray, Gam: np.ndarray, nsub: int,
                    torque_driven: bool, x0=None) -> np.ndarray:
    """The kernel's loop (``_run``) on ``u`` with ``nsub`` internal steps per sample and the
    discretisation ``Phi``, ``Gam`` of :func:`discretize`; from ``x0`` (default rest)."""
    x = np.zeros(3) if x0 is None else np.ascontiguousarray(x0, dtype=float)
    return _compiled("run")(np.ascontiguousarray(u, dtype=float),
                            np.ascontiguousarray(p, dtype=float), np.ascontiguousarray(Phi),
                            np.ascontiguousarray(Gam), int(nsub), bool(torque_driven), x)


def _compiled(name: str):
    """Compiled function ``name`` of :data:`pmdcid.simulate.aot.EXPORTS` from this module: the
    ahead-of-time build when it matches these sources, numba's JIT otherwise."""
    ahead = aot.load()
    if ahead is not None:
        return getattr(ahead, name)
    return {"run": _run, "expm_small": expm_small}[name]


__all__ = ["MAX_STEPS", "WorkBoundError", "bounded_for", "check_work", "choose_substeps",
           "discretize", "run_discretized", "run_kernel", "system_matrix", "FS", "BC"]
