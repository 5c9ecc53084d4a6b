"""Each log's initial state: a log need not start at rest.

A real log often starts with the rotor turning (closed-loop steps, a trimmed start, a previous
run still coasting). Simulated from rest it is wrong for a whole mechanical time constant, and a
fit then credits the start to friction, dead time or a "speed offset". The state at the first
sample, x0 = (i [A], omega [rad/s], theta [rad]), is taken from the measured first samples:

- theta: the first measured angle (an encoder's zero is arbitrary);
- i: the first measured current (voltage-driven logs with a current sensor); without one, 0
  at rest, and on a start clearly turning the current at which the armature's lag has
  settled, ``L di/dt = 0``: ``(v - ke omega)/R`` for the first input and speed and each
  parameter set's own R and ke (:func:`settled_start`; :func:`initial_state` marks it NaN).
  A rotor turning at its first sample has been driven for a while, and the electrical lag
  settles in a few L/R, a mechanical time constant's fraction; a start at i = 0 would drop
  the torque for L/R (measured on ``bench/lawlag.py --family share03``, back-EMF 30 % of the
  per-volt damping, L/R 4 ms: the true parameters 306 chi-square units above the fit's on
  the 5 -> 15 V step that starts turning, J' +5.8 % at 12.8 standard errors);
- omega: the speed AT the first sample (:func:`head_speed`): the mean of the longest run of
  first samples (at most :data:`HEAD`) over which the speed holds within its noise, so a rotor
  accelerating over the head (an input applied to a rotor at rest at the first sample: 2.1
  rad/s read as the start of a 50 Hz log of the paper motor at +12 V by the mean of five) is
  read at its first samples, and a steady start averages its noise down. A start within noise
  of zero, or under 10 % of the log's speed range, is exactly at rest (the kernel's stick-slip
  test needs omega = 0 exactly), and so is a constant reading while nothing drives the rotor
  (a sensor bias: an undriven rotor that turns slows down); a start clearly turning is a free
  parameter of the simulation-error fits (:func:`moving_start`), started there. fit-mechanical
  takes a log whose input is held from its first sample as a step from 0 there by the same
  test (:func:`start_speed` is 0).
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.simulate.layout import KE, VB, VMAX, R

#: first samples the starting speed is read from (at most)
HEAD = 5
#: a starting speed within this many standard errors of zero is a start at rest
REST_SIGMAS = 4.0
#: ... and so is one under this fraction of the log's speed range (99th percentile of |omega|):
#: it decays within one time constant and is not worth a parameter, and a speed derived from
#: the angle is least reliable at the log's edge (EMPS starts at 8 mm/s, 6.5 % of its range)
MOVING_FRACTION = 0.10
#: half-width, in standard errors, of the intervals :func:`head_speed` intersects
HOLD_SIGMAS = 1.5


def _head(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x[:HEAD], float)
    return x[np.isfinite(x)]


def head_speed(head: np.ndarray, sigma: float) -> tuple[float, float]:
    """The speed at the first of the samples ``head`` (finite, in order) whose white noise has
    std ``sigma``, and its standard error: the mean of the first m samples, m the largest for
    which the intervals mean +- :data:`HOLD_SIGMAS` standard errors (sigma/sqrt(k)) of every
    k <= m samples share a point (the intersection of confidence intervals): a speed that holds
    is averaged over the whole head, one that changes (a rotor accelerating from rest, a start
    trimmed in a transient) is read before it has moved by more than its noise. One rule for
    any log: no threshold on the acceleration, and an exact log (sigma 0) is read at its first
    sample."""
    sigma = sigma if math.isfinite(sigma) and sigma > 0.0 else 0.0
    lo, hi, best, se = -math.inf, math.inf, float(head[0]), sigma
    total = 0.0
    for m, x in enumerate(head, start=1):
        total += float(x)
        mean, sd = total / m, sigma / math.sqrt(m)
        lo, hi = max(lo, mean - HOLD_SIGMAS * sd), min(hi, mean + HOLD_SIGMAS * sd)
        if lo > hi:
            break
        best, se = mean, sd
    return best, se


def start_speed(log, sigma: float | None = None) -> float:
    """Measured speed at the first sample [rad/s] (:func:`head_speed`): 0 when it is within
    noise of rest, under :data:`MOVING_FRACTION` of the log's speed range, or a flat reading
    while undriven (a sensor bias)."""
    if not log.has("omega"):
        return 0.0
    head = _head(log["omega"])
    if head.size == 0:
        return 0.0
    if sigma is None:
        from pmdcid.io.derive import noise_std

        sigma = noise_std(np.asarray(log["omega"], float)[np.isfinite(log["omega"])])
    w0, sd = head_speed(head, float(sigma))
    if "omega" in log.derived:
        # a speed derived from the angle by a zero-phase filter is least reliable at the log's
        # edge (it already rises there when the rotor starts from rest): its head's spread
        sd = max(sd, float(np.std(head)))
    w = np.asarray(log["omega"], float)
    top = float(np.nanpercentile(np.abs(w), 99)) if w.size else 0.0
    if abs(w0) <= max(REST_SIGMAS * max(sd, 1e-12), MOVING_FRACTION * top):
        return 0.0
    if _undriven_and_flat(log, w, sd):
        return 0.0  # a constant reading with no drive is a sensor bias, not motion
    return w0


def _undriven_and_flat(log, w: np.ndarray, sd: float) -> bool:
    """No drive at the start (|u| under 1 % of its peak) and a speed that does not change over
    the first window: an undriven rotor that turns must slow down (friction), so the reading is
    a bias on the sensor."""
    u = np.asarray(log.u, float)
    peak = float(np.nanmax(np.abs(u))) if u.size else 0.0
    if peak > 0 and np.nanmax(np.abs(u[:HEAD])) > 0.01 * peak:
        return False
    n = min(max(4 * HEAD, len(w) // 20), 400, len(w))
    a, b = w[:HEAD], w[n - HEAD:n]
    a, b = a[np.isfinite(a)], b[np.isfinite(b)]
    if not (a.size and b.size):
        return False
    return abs(float(np.mean(b)) - float(np.mean(a))) <= 3.0 * max(sd, 1e-12) * math.sqrt(2.0)


def initial_state(log, sigma_omega: float | None = None) -> np.ndarray:
    """x0 = (i [A], omega [rad/s], theta [rad]) at the log's first sample (module docstring):
    i is NaN where no current is logged and the rotor turns, the current its lag settled at,
    which depends on the model (:func:`settled_start`, applied by every simulation)."""
    w0 = start_speed(log, sigma_omega)
    i0 = math.nan if w0 != 0.0 else 0.0
    if log.has("i") and log.drive == "v":
        head = _head(log["i"])
        i0 = float(head[0]) if head.size else 0.0
    th0 = 0.0
    if log.has("theta"):
        head = _head(log["theta"])
        th0 = float(head[0]) if head.size else 0.0
    return np.array([i0, w0, th0])


def settled_current(p: np.ndarray, u0: float, omega: float) -> float:
    """The armature current [A] at which its lag has settled (``L di/dt = 0``) under the input
    ``u0`` [V] at speed ``omega`` [rad/s]: ``(v - drop - ke omega)/R``, v the drive's voltage
    (clipped to +-vmax) and drop the brushes' (``brush_drop``), as :mod:`.terms` applies them;
    ``p``: the kernel's parameter vector (:data:`pmdcid.simulate.layout.NAMES`). 0 where R is
    not a positive number."""
    v = min(max(float(u0), -p[VMAX]), p[VMAX])
    drive = v - p[KE] * omega
    drop = min(max(drive, -p[VB]), p[VB]) if p[VB] > 0.0 else 0.0
    i = (drive - drop) / p[R] if p[R] > 0.0 else 0.0
    return float(i) if math.isfinite(i) else 0.0


def settled_start(x0, u0: float, p: np.ndarray, torque_driven: bool):
    """``x0`` with an unmeasured current (NaN, :func:`initial_state`) replaced: 0 where the
    kernel is driven by torque (its current plays no part), else :func:`settled_current` at
    the start's speed for the parameter vector ``p``; anything else returned as it is."""
    if x0 is None:
        return x0
    x = np.array(x0, dtype=float).ravel()
    if x.size == 0 or math.isfinite(x[0]):
        return x0
    x[0] = 0.0 if torque_driven else settled_current(p, u0, float(x[1]))
    return x


def true_start(x0: np.ndarray, vals: dict[str, float]) -> np.ndarray:
    """The kernel's starting state from a measured one, ``x0`` (:func:`initial_state`), for a
    model with parameter values ``vals``: a speed sensor's bias (``omega0``, speed_offset) is
    in the measured speed, not in the rotor's, so a moving start is taken back by it (a start
    at rest stays exactly at rest). A sensor delay needs nothing: the kernel's delayed reading
    holds the first state before t0, as the measurement does."""
    w0 = float(vals.get("omega0", 0.0))
    if x0[1] == 0.0 or w0 == 0.0 or not math.isfinite(w0):
        return x0
    out = np.array(x0, float)
    out[1] -= w0
    return out


def moving_start(x0: np.ndarray) -> bool:
    """True when the log starts turning (its starting speed is then fitted)."""
    return x0[1] != 0.0


__all__ = ["head_speed", "initial_state", "moving_start", "settled_current", "settled_start",
           "start_speed", "true_start"]
