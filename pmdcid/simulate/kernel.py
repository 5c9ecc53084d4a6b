"""The one simulation kernel: exact piecewise-linear stepping with true stick-slip, compiled.

State x = (i [A], omega [rad/s], theta [rad]). Between events the model is linear with constant
forcing, so each internal step of length h uses the exact discretisation
``x+ = Phi x + Gamma f`` (matrix exponential of the augmented system, compiled), computed once
per call for the two dead-zone modes (and over the finer step). Input is zero-order held over
each sample period.
Non-linear terms (Coulomb sign, Stribeck, quadratic drag, cogging, brush drop, the dead-zone jump)
are evaluated at the start of each internal step and held over it; a step whose current crosses
the dead zone's break point is taken again as :data:`EDGE_REFINE` finer steps (where the torque
is pinned at the edge it chatters on that finer scale); a rotor at rest stays exactly
at rest while the torque on it is within the static friction level (no tanh smoothing), and a
rotor whose speed would cross zero is stopped there and re-tested for sticking.

With bc = dz = 0 and no effects the kernel is exact to rounding for any step; with them it
converges at first order in h at the events.

Effects may own extra states (:data:`pmdcid.simulate.layout.STATES`): LuGre's bristle deflection
z. With LuGre on (sigma0 > 0) the stick-slip logic is replaced by the bristles' friction
sigma0 z + sigma1 dz/dt + bv omega (sigma1's omega part in the exact linear step, the rest held),
and z is stepped exactly with its rate held (:func:`pmdcid.simulate.terms.bristle_step`). Off, z
stays at its start and every other state is bit-for-bit the 3-state kernel's.
"""

from __future__ import annotations

import math
import threading

import numpy as np

from pmdcid.simulate import compiled
from pmdcid.simulate.layout import (
    BC,
    BV,
    DZ_OFFSET,
    DZ_SLOPE,
    FS,
    KE,
    KM,
    LINEAR,
    NSTATE,
    J,
    L,
    R,
    state_vector,
)
from pmdcid.simulate.lazyjit import njit
from pmdcid.simulate.substeps import check_work, choose_substeps
from pmdcid.simulate.terms import (
    armature_voltage,
    bristle_rate,
    bristle_step,
    dead_zone,
    dead_zone_engaged,
    drive_voltage,
    friction_guarded,
    instant_current,
    load_torque,
    lugre_damping,
    lugre_held_friction,
    lugre_on,
    sgn,
    sliding_friction,
    static_friction,
)

#: finer steps a step that crosses the dead zone's break point is taken again in. The mode is
#: still taken at each (finer) step's start, so where the dead zone is above the friction a
#: running rotor needs and pins the torque at its edge, the current chatters in and out on
#: h/16: 0.39 -> 0.094 rad/s of ripple on tests/simulate/test_kernel.py's pinned motor, the
#: events (and the fit's cost) 16 times finer. Measured on bench/lawlag.py's hobby and large
#: motors (24 runs): bv', bc' inside 2 standard errors 10, 8 -> 15, 15 (docs/model.md)
EDGE_REFINE = 16


@njit(cache=True, inline="always")
def augmented_matrix(p, engaged, torque_driven, h, M):  # pragma: no cover - compiled
    """Fill M (6x6) with [[A h, I h], [0, 0]]: A the continuous-time system matrix of
    x = (i, omega, theta) in one dead-zone mode, h [s] the internal step.

    Voltage-driven: L di/dt = v - R i - ke omega; J domega/dt = k*km*i - bv omega + ...
    With L = 0 the current follows the voltage at once, i = (v - ke omega)/R
    (:func:`pmdcid.simulate.terms.instant_current`): the current row is zero and, engaged,
    the back-EMF's k km ke/R omega joins bv (the voltage's part is forcing, :func:`_forcing`).
    Torque-driven: the current row is zero (the current is not simulated). LuGre's micro-damping
    sigma1 [N m s/rad] adds to bv while LuGre is on (:func:`pmdcid.simulate.terms.lugre_damping`).
    """
    for r in range(6):
        for c in range(6):
            M[r, c] = 0.0
    damping = p[BV] + lugre_damping(p)
    if not torque_driven and p[L] > 0.0:
        M[0, 0] = -p[R] / p[L] * h
        M[0, 1] = -p[KE] / p[L] * h
        if engaged:
            M[1, 0] = p[DZ_SLOPE] * p[KM] / p[J] * h
    elif not torque_driven and engaged:  # L = 0: the back-EMF's torque in the linear step
        damping += p[DZ_SLOPE] * p[KM] * p[KE] / p[R]
    M[1, 1] = -damping / p[J] * h
    M[2, 1] = h
    for r in range(3):
        M[r, 3 + r] = h


@njit(cache=True)
def expm_small(M, E):  # pragma: no cover - compiled
    """E = exp(M) for the 6x6 matrix M: scaling and squaring of a Taylor series.

    Scaled to norm <= 1/2 and summed to 20 terms (truncation < 1e-25 relative), then squared
    back. Used instead of ``scipy.linalg.expm`` because for 6x6 matrices the BLAS thread pool
    makes scipy's call cost milliseconds; this costs about a microsecond.
    """
    norm = 0.0
    for r in range(6):
        row = 0.0
        for c in range(6):
            row += abs(M[r, c])
        norm = max(norm, row)
    s = 0
    if norm > 0.5:
        s = int(math.ceil(math.log2(norm / 0.5)))
    scale = 2.0**s
    A = np.empty_like(M)
    term = np.empty_like(M)
    tmp = np.empty_like(M)
    for r in range(6):
        for c in range(6):
            A[r, c] = M[r, c] / scale
            term[r, c] = 1.0 if r == c else 0.0
            E[r, c] = term[r, c]
    for k in range(1, 21):
        _matmul(term, A, tmp)
        for r in range(6):
            for c in range(6):
                term[r, c] = tmp[r, c] / k
                E[r, c] = E[r, c] + term[r, c]
    for _ in range(s):
        _matmul(E, E, tmp)
        for r in range(6):
            for c in range(6):
                E[r, c] = tmp[r, c]


@njit(cache=True, inline="always")
def _matmul(X, Y, Z):  # pragma: no cover - compiled; plain loops, no BLAS call for tiny matrices
    """Z = X Y for 6x6 matrices (Z distinct from X and Y)."""
    for r in range(6):
        for c in range(6):
            Z[r, c] = 0.0
    for r in range(6):
        for k in range(6):
            x = X[r, k]
            for c in range(6):
                Z[r, c] += x * Y[k, c]


@njit(cache=True)
def discretize_into(p, h, torque_driven, Phi, Gam):  # pragma: no cover - compiled
    """Exact zero-order-hold discretisation over h [s] for both dead-zone modes, into Phi and
    Gam (4, 3, 3): ``Phi = expm(A h)``, ``Gam = int_0^h expm(A s) ds`` (from the augmented
    6x6 exponential). Mode 0 is the dead zone engaged (torque passes), mode 1 disengaged; modes
    2 and 3 the same over h / :data:`EDGE_REFINE` (a step that crosses the dead zone's edge)."""
    M = np.zeros((6, 6))
    E = np.zeros((6, 6))
    for m in range(4):
        hm = h
        if m >= 2:
            hm = h / EDGE_REFINE
        augmented_matrix(p, m == 0 or m == 2, torque_driven, hm, M)
        expm_small(M, E)
        for r in range(3):
            for c in range(3):
                Phi[m, r, c] = E[r, c]
                Gam[m, r, c] = E[r, 3 + c]


def discretize(p: np.ndarray, h: float, torque_driven: bool) -> tuple[np.ndarray, np.ndarray]:
    """:func:`discretize_into` new arrays: (Phi, Gamma), each (4, 3, 3)."""
    Phi = np.empty((4, 3, 3))
    Gam = np.empty((4, 3, 3))
    _compiled("discretize_into")(np.ascontiguousarray(p, dtype=float), float(h),
                                 bool(torque_driven), Phi, Gam)
    return Phi, Gam


_DISCRETE: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
_DISCRETE_SIZE = 64
_DISCRETE_LOCK = threading.Lock()


def discretize_cached(p: np.ndarray, h: float, torque_driven: bool):
    """:func:`discretize`, remembered for the last few linear parts (``layout.LINEAR``).

    A refit of friction or sensor parameters leaves the linear part unchanged and logs share
    sample rates: the cache removes most of the 6x6 exponentials of a fit (which also suffer
    from BLAS thread contention on a loaded machine). The arrays returned are shared: read only.
    """
    key = (tuple(float(p[k]) for k in LINEAR), float(h), bool(torque_driven))
    hit = _DISCRETE.get(key)
    if hit is None:
        hit = discretize(p, h, torque_driven)
        with _DISCRETE_LOCK:  # fits simulate from several threads (fit/fdjac.py)
            while len(_DISCRETE) >= _DISCRETE_SIZE:
                _DISCRETE.pop(next(iter(_DISCRETE)))
            _DISCRETE[key] = hit
    return hit


@njit(cache=True, inline="always")
def _record(out, k, i, w, th, z):  # pragma: no cover - compiled
    """Row k of the output: the state (i, omega, theta, z) at the sample instant."""
    out[k, 0] = i
    out[k, 1] = w
    out[k, 2] = th
    out[k, 3] = z


@njit(cache=True, inline="always")
def sample_input(p, uk, torque_driven):  # pragma: no cover - compiled
    """(torque input [N m], voltage the drive applies [V]) held over one sample of input uk."""
    if torque_driven:
        return uk, 0.0
    return 0.0, drive_voltage(p, uk)


@njit(cache=True, inline="always")
def _forcing(p, torque_driven, eng, vin, i, w, td, tl, fric):  # pragma: no cover - compiled
    """The held forcing of one step: (dead-zone mode, electrical row [A/s], mechanical row
    [rad/s^2]) from the driving torque td, load tl and held friction fric [N m]."""
    if torque_driven:
        return 0, 0.0, (td - tl - fric) / p[J]
    if p[L] > 0.0:
        fe = armature_voltage(p, vin, w) / p[L]
        fv = 0.0
    else:  # L = 0: no current row; the voltage drives the rotor directly while engaged
        fe = 0.0
        fv = p[DZ_SLOPE] * p[KM] * armature_voltage(p, vin, w) / p[R]
    if eng:
        m = 0
        fm = p[DZ_OFFSET] * sgn(i) + fv
    else:
        m = 1
        fm = 0.0
    return m, fe, (fm - tl - fric) / p[J]


@njit(cache=True, inline="always")
def _linear_step(Phi, Gam, m, i, w, th, fe, fm):  # pragma: no cover - compiled
    """One exact step of (i, omega, theta) in dead-zone mode m under held forcing (fe, fm)."""
    i1 = Phi[m, 0, 0] * i + Phi[m, 0, 1] * w + Gam[m, 0, 0] * fe + Gam[m, 0, 1] * fm
    w1 = (Phi[m, 1, 0] * i + Phi[m, 1, 1] * w + Gam[m, 1, 0] * fe
          + Gam[m, 1, 1] * fm)
    th1 = (th + Phi[m, 2, 0] * i + Phi[m, 2, 1] * w + Gam[m, 2, 0] * fe
           + Gam[m, 2, 1] * fm)
    return i1, w1, th1


@njit(cache=True, inline="always")
def _stick_core(p, Phi, Gam, mode0, torque_driven, guarded, tin, vin, i, w,
                th):  # pragma: no cover - compiled
    """One internal step of the stick-slip loop: (i [A], omega [rad/s], theta [rad]) after it,
    under the held torque input tin [N m] or drive voltage vin [V].

    True stiction: a rotor at rest stays at rest while the torque on it is within the static
    friction level. At rest the current moves with omega = 0; if the torque it builds breaks
    the rotor free within this step, a moving step is tried, accepted only if the rotor then
    moves in the driving direction (second-order breakaway timing). A speed that would cross
    zero within the step goes on through the crossing or sticks there (:func:`_through_zero`).
    ``guarded``: :func:`pmdcid.simulate.terms.friction_guarded` of ``p``. ``mode0``: 0 for a
    whole internal step, 2 for one of its :data:`EDGE_REFINE` parts (:func:`discretize_into`'s
    modes).
    """
    if torque_driven:
        tm = tin
    else:
        tm = p[KM] * i
    eng = dead_zone_engaged(p, tm)
    td = dead_zone(p, tm)
    tl = load_torque(p, th)
    fstat = static_friction(p)
    tentative = False
    i_stuck = i
    if w == 0.0:
        net = td - tl
        if abs(net) <= fstat:
            if not torque_driven and p[L] > 0.0:  # disengaged: no coupling to omega
                ve = armature_voltage(p, vin, 0.0)
                i_stuck = Phi[mode0 + 1, 0, 0] * i + Gam[mode0 + 1, 0, 0] * ve / p[L]
                net = dead_zone(p, p[KM] * i_stuck) - tl
            if abs(net) <= fstat:
                return i_stuck, w, th
            tentative = True
        direction = sgn(net)
    else:
        direction = sgn(w)
    fric = sliding_friction(p, w, direction, guarded)
    m, fe, fm = _forcing(p, torque_driven, eng, vin, i, w, td, tl, fric)
    i1, w1, th1 = _linear_step(Phi, Gam, mode0 + m, i, w, th, fe, fm)
    if tentative and w1 * direction <= 0.0:
        return i_stuck, w, th  # did not break free after all: stays at rest
    if fstat > 0.0 and w1 * direction < 0.0:  # the speed would cross zero within the step
        i1, w1, th1 = _through_zero(p, Phi, Gam, mode0, torque_driven, guarded, tin, vin, i, w,
                                    th, i1, w1, th1)
    if torque_driven:
        i1 = 0.0
    elif p[L] == 0.0:
        i1 = instant_current(p, vin, w1)
    return i1, w1, th1


@njit(cache=True, inline="always")
def _through_zero(p, Phi, Gam, mode0, torque_driven, guarded, tin, vin, i, w, th, i1, w1,
                  th1):  # pragma: no cover - compiled
    """The end of a step (i [A], omega [rad/s], theta [rad]) whose speed would cross zero: at
    the crossing (the fraction s = w / (w - w1) of the step, i and theta read there linearly)
    the rotor sticks while the torque on it is within the static friction level; else it goes
    on the other way for the rest of the step, a step from the crossing under the reversed
    friction taken for the remaining fraction 1 - s (linearly). The end state is continuous in
    s: a crossing that moves across an internal step's boundary moves the trajectory by a
    little, not by the rest of a step (stopping at zero and breaking away only at the next step
    lost up to one internal step at every reversal: a cliff in the fits' cost that stopped a
    local stage 14 % off in bc on a two-level PRBS)."""
    s = w / (w - w1)
    ic = i + s * (i1 - i)
    if not torque_driven and p[L] == 0.0:
        ic = instant_current(p, vin, 0.0)
    thc = th + s * (th1 - th)
    if torque_driven:
        tm = tin
    else:
        tm = p[KM] * ic
    td = dead_zone(p, tm)
    tl = load_torque(p, thc)
    net = td - tl
    if abs(net) <= static_friction(p):
        return i1, 0.0, thc
    direction = sgn(net)
    fric = sliding_friction(p, 0.0, direction, guarded)
    m, fe, fm = _forcing(p, torque_driven, dead_zone_engaged(p, tm), vin, ic, 0.0, td, tl, fric)
    i2, w2, th2 = _linear_step(Phi, Gam, mode0 + m, ic, 0.0, thc, fe, fm)
    r = 1.0 - s
    if r * w2 * direction <= 0.0:
        return i1, 0.0, thc
    return ic + r * (i2 - ic), r * w2, thc + r * (th2 - thc)


@njit(cache=True, inline="always")
def stick_substep(p, Phi, Gam, torque_driven, guarded, tin, vin, i, w,
                  th):  # pragma: no cover - compiled
    """One internal step of the stick-slip loop (:func:`_stick_core`), taken again as
    :data:`EDGE_REFINE` finer steps where the current crosses the dead zone's break point.
    With L = 0 the current is the voltage's at once (:func:`pmdcid.simulate.terms.instant_current`),
    at the step's start under this sample's input."""
    if not torque_driven and p[L] == 0.0:
        i = instant_current(p, vin, w)
    i1, w1, th1 = _stick_core(p, Phi, Gam, 0, torque_driven, guarded, tin, vin, i, w, th)
    if torque_driven or dead_zone_engaged(p, p[KM] * i) == dead_zone_engaged(p, p[KM] * i1):
        return i1, w1, th1
    for _ in range(EDGE_REFINE):
        i, w, th = _stick_core(p, Phi, Gam, 2, torque_driven, guarded, tin, vin, i, w, th)
    return i, w, th


@njit(cache=True, inline="always")
def lugre_substep(p, Phi, Gam, torque_driven, tin, vin, i, w, th,
                  z):  # pragma: no cover - compiled
    """One internal step of the LuGre loop: (i [A], omega [rad/s], theta [rad], z [rad]) after
    it, under the held torque input tin [N m] or drive voltage vin [V].

    No sticking test: the bristles (deflection z) hold a rotor at rest. Friction sigma0 z +
    sigma1 dz/dt + bv omega (+ drag, viscous asymmetry): (bv + sigma1) omega is in the exact
    linear step (:func:`augmented_matrix`), the rest is held over the step
    (:func:`pmdcid.simulate.terms.lugre_held_friction`); then z is stepped exactly with the
    step's mean speed (:func:`pmdcid.simulate.terms.bristle_step`). The dead zone acts on the
    driving torque as in the stick-slip loop.
    """
    if torque_driven:
        tm = tin
    else:
        if p[L] == 0.0:
            i = instant_current(p, vin, w)
        tm = p[KM] * i
    a = bristle_rate(p, w)
    fric = lugre_held_friction(p, w, z, a)
    m, fe, fm = _forcing(p, torque_driven, dead_zone_engaged(p, tm), vin, i, w,
                         dead_zone(p, tm), load_torque(p, th), fric)
    i1, w1, th1 = _linear_step(Phi, Gam, m, i, w, th, fe, fm)
    h = Gam[0, 2, 2]  # the angle's own input column integrates 1 over the step: exactly h
    z1 = bristle_step(z, a, h, th1 - th)
    if torque_driven:
        i1 = 0.0
    elif p[L] == 0.0:
        i1 = instant_current(p, vin, w1)
    return i1, w1, th1, z1


@njit(cache=True, nogil=True)
def _run(u, p, Phi, Gam, nsub, torque_driven, x0):  # pragma: no cover - compiled
    """States (n, NSTATE) at the sample instants from ``x0`` (the base triple or a full state):
    the stick-slip loop, or the LuGre loop when LuGre is on (two loops: the stick-slip one, the
    hot path of every fit, stays free of LuGre's branches)."""
    return _run_into(u, p, Phi, Gam, nsub, torque_driven, x0, np.empty((u.shape[0], NSTATE)))


@njit(cache=True)
def _run_into(u, p, Phi, Gam, nsub, torque_driven, x0, out):  # pragma: no cover - compiled
    """:func:`_run` writing the states into ``out`` (n, NSTATE), which it returns."""
    _run_states(u, p, Phi, Gam, nsub, torque_driven, x0, out)
    return out


@njit(cache=True, inline="always")
def _run_states(u, p, Phi, Gam, nsub, torque_driven, x0, out):  # pragma: no cover - compiled
    """The states (n, NSTATE) at the sample instants into ``out``, from ``x0`` (the base
    triple or a full state): the LuGre loop when LuGre is on, else the stick-slip loop,
    compiled with and without the friction curve's guard."""
    z0 = x0[3] if x0.shape[0] > 3 else 0.0
    if lugre_on(p):
        _run_lugre(u, p, Phi, Gam, nsub, torque_driven, x0[0], x0[1], x0[2], z0, out)
    elif friction_guarded(p):
        _run_stick(u, p, Phi, Gam, nsub, torque_driven, x0[0], x0[1], x0[2], z0, out, True)
    else:
        _run_stick(u, p, Phi, Gam, nsub, torque_driven, x0[0], x0[1], x0[2], z0, out, False)


@njit(cache=True, inline="always")
def _run_stick(u, p, Phi, Gam, nsub, torque_driven, i, w, th, z, out,
               guarded):  # pragma: no cover
    """The stick-slip loop (:func:`stick_substep`). LuGre is off: its bristle deflection z is
    not integrated (stays at its start). ``guarded``: passed as a constant so that the loop is
    compiled twice, once without the friction curve and its positivity hold (on the critical
    path of every step: ~8 ns of 20)."""
    for k in range(u.shape[0]):
        _record(out, k, i, w, th, z)
        tin, vin = sample_input(p, u[k], torque_driven)
        for _ in range(nsub):
            i, w, th = stick_substep(p, Phi, Gam, torque_driven, guarded, tin, vin, i, w, th)


@njit(cache=True)
def _run_lugre(u, p, Phi, Gam, nsub, torque_driven, i, w, th, z, out):  # pragma: no cover
    """The LuGre loop (:func:`lugre_substep`)."""
    for k in range(u.shape[0]):
        _record(out, k, i, w, th, z)
        tin, vin = sample_input(p, u[k], torque_driven)
        for _ in range(nsub):
            i, w, th, z = lugre_substep(p, Phi, Gam, torque_driven, tin, vin, i, w, th, z)


def run_kernel(u: np.ndarray, dt: float, p: np.ndarray, torque_driven: bool = False,
               nsub: int | None = None, x0=None, out: np.ndarray | None = None) -> np.ndarray:
    """Simulate from ``x0`` (default rest) under the zero-order-held input ``u`` sampled at ``dt``.

    Returns an (n, NSTATE) array of the states :data:`pmdcid.simulate.layout.STATES` (i [A],
    omega [rad/s], theta [rad], then effect states: LuGre's z [rad]) at the sample instants; row
    k is the state at t_k, before input u[k] is applied over [t_k, t_k + dt). ``x0``: the base
    triple or a full state (:func:`pmdcid.simulate.layout.state_vector`).

    ``out``: a C-contiguous float (n, NSTATE) array to write the states into and return (a fit
    simulating the same log many times reuses one: no fresh pages of a large array to fault in
    every call). Whatever the caller keeps of a previous result in ``out`` is overwritten.
    """
    if nsub is None:
        nsub = choose_substeps(dt, p)
    check_work(len(u), dt, nsub, p)
    h = dt / nsub
    Phi, Gam = discretize_cached(p, h, torque_driven)
    x = state_vector(x0)
    u = np.ascontiguousarray(u, dtype=float)
    p = np.ascontiguousarray(p, dtype=float)
    if out is None:
        return _compiled("run")(u, p, Phi, Gam, int(nsub), bool(torque_driven), x)
    if out.shape != (len(u), NSTATE) or out.dtype != float or not out.flags.c_contiguous:
        raise ValueError(f"out must be a C-contiguous float array of shape {(len(u), NSTATE)}")
    return _compiled("run_into")(u, p, Phi, Gam, int(nsub), bool(torque_driven), x, out)


def _compiled(name: str):
    """Compiled function ``name`` (``run``, ``run_into``, ``discretize_into``) of this module:
    the C build of its generated source when it matches these sources
    (:mod:`pmdcid.simulate.compiled`), numba's JIT otherwise."""
    fast = compiled.load()
    if fast is not None:
        return getattr(fast, name)
    return {"run": _run, "discretize_into": discretize_into, "run_into": _run_into}[name]


__all__ = ["discretize", "discretize_cached", "discretize_into", "expm_small", "lugre_substep",
           "run_kernel", "sample_input", "stick_substep", "FS", "BC"]
