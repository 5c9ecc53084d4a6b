"""fit-mechanical, one step at a time: the paper's first-order fit and the second-order fit with
the electrical lag held, from rest or from a moving start (:func:`fit_step`).

A step (:func:`~pmdcid.identify.steps.find_steps`) is an interval of constant voltage after a
change, up to the next change. Its response is fitted from the speed at the step instant,
``omega(t) = omega_inf + (omega0 - omega_inf) exp(-(t - t0 - d)/tau)`` (first order; exact for
a first-order plant whatever came before), not from rest: a log that starts turning, or a step
down, is not mistaken for a breakaway and a dead time. Only a step from rest (rotor still, input
0 before) can show a breakaway (beta < 1 in :func:`~pmdcid.identify.steps.two_lag`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.fit.covariance import standard_error
from pmdcid.identify.freerun import first_diff_noise_std
from pmdcid.identify.steps import (
    MIN_PLATEAU_SAMPLES,
    StepInfo,
    fit_first_order,
    lsq,
    strejc,
    two_lag,
)

#: a step whose steady speed is within this many noise std of zero did not move the rotor
MOVE_SIGMAS = 8.0
#: a plateau must last this many time constants (plus dead time) for its steady speed to be
#: read rather than extrapolated (5 % left at 3)
SETTLE_TAUS = 3.0


def paper_mechanical(kmot: float, tau_mot: float, km: float, r: float) -> tuple[float, float]:
    """The paper's eqs. (13)-(14): b = km/(Kmot R) [N m s/rad], J = tau_mot b [kg m^2].

    Kmot [rad/s per V], tau_mot [s], km [N m/A], R [ohm].
    """
    b = km / (kmot * r)
    return b, tau_mot * b


@dataclass
class MechStep:
    """One step: amplitude [V, or N m for a torque step], moved?, first-order (paper) and
    second-order fits."""

    path: str
    amplitude: float
    moved: bool
    kmot: float = math.nan
    tau_mot: float = math.nan
    b: float = math.nan
    J_paper: float = math.nan
    omega_ss: float = math.nan
    omega_ss_se: float = math.nan
    tau_m: float = math.nan
    tau_m_se: float = math.nan
    dead_time: float = math.nan
    beta: float = math.nan
    strejc_order: int = 0
    level: float = math.nan  # input level of the plateau [V]
    t0: float = math.nan  # time of the step [s]
    from_rest: bool = True
    omega0: float = math.nan  # speed at the step instant [rad/s]
    note: str = ""  # why a step is not used
    #: a plateau too short to settle: (how long the input holds [s], the first-order time
    #: constant [s])
    short: tuple[float, float] | None = None
    #: a level read at the log's start (the rotor turning, the input held before the first
    #: step: :func:`head_level`): no step, only its steady speed enters the line
    head: bool = False
    chisqr: float = 0.0
    ndata: int = 0
    unit: str = "V"  # the input's unit: "V" or "N m" (a torque step)


def _second_order(t, w, step, tau_e, st, sigma, breakaway=True):
    s = t - step.t0
    dt = float(t[1] - t[0])
    span = float(t[-1] - step.t0)
    tau0 = max(st.tau - tau_e, 2 * tau_e) if math.isfinite(st.tau) else 0.1 * span
    names = ("y0", "wss", "tau_m", "d", "beta")
    x0 = [st.initial, st.final - st.initial, tau0, min(st.tu, 0.5 * tau0)
          if math.isfinite(st.tu) else 0.0, 0.9]
    lo = np.array([-np.inf, -np.inf, 1.01 * tau_e + 0.05 * dt, 0.0, 0.0 if breakaway else
                   1.0 - 1e-9])
    hi = np.array([np.inf, np.inf, 10 * span, 0.5 * span, 1.0])
    if not breakaway:  # a moving rotor does not break free: the current's lag alone
        x0[4] = 1.0

    def resid(x):
        y0, wss, tm, d, beta = x
        return (y0 + wss * np.where(s > d, two_lag(s - d, tm, tau_e, beta), 0.0) - w) / sigma

    return lsq(resid, x0, lo, hi, names)


def speed_noise(w: np.ndarray) -> float:
    """Speed noise std [rad/s]: sample-to-sample scatter, at least an encoder quantum's."""
    d = np.abs(np.diff(w))
    q = float(np.min(d[d > 0])) if np.any(d > 0) else 0.0
    return max(first_diff_noise_std(w), q / math.sqrt(12.0), 1e-6 * float(np.max(np.abs(w))), 1e-12)


def window(log, step, pre=5):
    """(t, omega, step) of one step's interval: a few samples before the onset (the speed at
    the step instant) to the end of its plateau; the step re-indexed into the window."""
    a = max(step.prev_start, step.onset - pre)
    e = step.end if step.end is not None else log.n
    w = np.asarray(log["omega"], float)
    st = StepInfo(step.onset - a, step.t0, step.before, step.after, e - a, 0, step.before_se)
    return log.t[a:e], w[a:e], st


def fit_step(log, step, tau_e, km, R, sig, warns):
    """One step (from rest or from a moving start): first-order and second-order fits; returns
    (MechStep, (time from onset, speed change, torque, noise) for the joint fit or None)."""
    t, w, st_w = window(log, step)
    ms = MechStep(log.path, step.amplitude, False, level=step.after, t0=step.t0,
                  unit="N m" if log.drive == "tau" else "V")
    where = f"{log.path} (step to {step.after:.3g} {ms.unit} at t = {step.t0:.4g} s)"
    st = strejc(t, w, st_w)
    w0, w_end = st.initial, st.final
    # from rest: the rotor still and the input 0 before (within 2 % of the level, or 4 standard
    # errors of the level before: a measured input's noise)
    ms.from_rest = abs(w0) <= MOVE_SIGMAS * sig and abs(step.before) <= max(
        0.02 * abs(step.after), 4 * step.before_se)
    if abs(w_end) <= MOVE_SIGMAS * sig or step.after == 0.0:
        # a step to no input at all coasts towards rest: no steady speed per volt to read,
        # whether or not the log ends before the rotor stops (newrigs current-sag seed 16: a
        # 12 -> 0 V step still at 88 rpm when the log ended divided by the level 0)
        ms.note = "did not move" if ms.from_rest else "coasts to rest"
        return ms, None
    cf1 = fit_first_order(t, w, st_w, st)
    plateau = float(t[-1] - step.t0)
    if not plateau >= SETTLE_TAUS * (cf1["tau"] + cf1["d"]):
        # said once per log by mechanical._short_warnings (a rich log holds dozens)
        ms.note = "plateau too short"
        ms.short = (plateau, float(cf1["tau"]))
        return ms, None
    ms.moved, ms.strejc_order = True, st.order
    ms.omega0, ms.tau_mot = cf1["y0"], cf1["tau"]
    # the paper's Kmot: steady speed per volt of the plateau (from rest: omega_ss/dV)
    ms.kmot = (cf1["y0"] + cf1["dy"]) / step.after
    ms.b, ms.J_paper = paper_mechanical(ms.kmot, ms.tau_mot, km, R)
    cf2 = _second_order(t, w, st_w, tau_e, st, sig, breakaway=ms.from_rest)
    ms.omega_ss, ms.omega_ss_se = cf2["y0"] + cf2["wss"], math.hypot(cf2.se("wss"),
                                                                       cf2.se("y0"))
    ms.tau_m, ms.tau_m_se = cf2["tau_m"], cf2.se("tau_m")
    ms.dead_time, ms.beta = cf2["d"], cf2["beta"]
    ms.chisqr, ms.ndata = cf2.sigma**2 * max(cf2.ndata - 5, 1), cf2.ndata
    if not no_transient(ms, float(t[1] - t[0]), where, warns) and ms.from_rest:
        return ms, (t - step.t0, w - cf2["y0"], km * step.after / R, sig)
    return ms, None


def no_transient(ms: MechStep, dt: float, where: str, warns: list) -> bool:
    """Whether the step's speed shows no transient in its samples: a fitted time constant
    (first- or second-order) under one sample period ``dt`` [s] (a speed already at its level
    at the first sample: a log that starts turning, taken for a step from rest). The samples
    cannot show such a time constant: the step's tau_mot, tau_m and J_paper are then NaN (not
    read, left out of the means) and only its steady speed enters the steady-speed line."""
    tau = min((x for x in (ms.tau_mot, ms.tau_m) if math.isfinite(x)), default=math.inf)
    if tau >= dt:
        return False
    ms.tau_mot = ms.tau_m = ms.tau_m_se = ms.J_paper = math.nan
    warns.append(f"{where}: the speed is at its level from the first sample (a time constant "
                 f"of {tau:.3g} s, under one sample period, {dt:.3g} s): no transient to read J "
                 "from; only its steady speed is used")
    return True


def head_level(log, step, w, sig, tau, tau_se) -> MechStep | None:
    """The level a log that starts turning holds before its first ``step``: its steady speed
    [rad/s] read from its approach ``omega(t) = omega_ss + (omega(0) - omega_ss) exp(-t/tau)``
    with the steps' mechanical time constant ``tau`` [s] (one for every level of a linear
    plant), a least-squares line in (omega_ss, omega(0) - omega_ss). Its standard error is the
    fit's (scaled up by the residual's scatter beyond ``sig`` [rad/s]) and what ``tau_se`` [s]
    moves it. A settled start gives its mean speed; a short one, a wide error. None when the
    head is under :data:`~pmdcid.identify.steps.MIN_PLATEAU_SAMPLES` samples or the time
    constant is unknown."""
    n = step.onset
    if n < MIN_PLATEAU_SAMPLES or not (math.isfinite(tau) and tau > 0):
        return None
    s = log.t[:n] - log.t[0]
    y = np.asarray(w[:n], float)

    def solve_at(tm):
        X = np.column_stack([np.ones(n), np.exp(-s / tm)])
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        return X, coef

    X, coef = solve_at(tau)
    resid = y - X @ coef
    s2 = max(float(resid @ resid) / max(n - 2, 1), sig**2)
    cov = np.linalg.pinv(X.T @ X) * s2
    se = standard_error(float(cov[0, 0]))  # NaN where not determined: kept off the line
    if math.isfinite(tau_se) and tau_se > 0:
        dt = min(tau_se, 0.5 * tau)
        se = math.hypot(se, 0.5 * (solve_at(tau + dt)[1][0] - solve_at(tau - dt)[1][0])
                        * tau_se / dt)
    return MechStep(log.path, 0.0, False, omega_ss=float(coef[0]), omega_ss_se=se,
                    tau_m=tau, level=step.before, t0=float(log.t[0]), from_rest=False,
                    omega0=float(coef[0] + coef[1]), note="level at the log's start",
                    head=True, ndata=n)
