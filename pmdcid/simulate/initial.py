"""Each log's initial state: a log need not start at rest.

A real log often starts with the rotor turning (closed-loop steps, a trimmed start, a previous
run still coasting). Simulated from rest it is wrong for a whole mechanical time constant, and a
fit then credits the start to friction, dead time or a "speed offset". The state at the first
sample, x0 = (i [A], omega [rad/s], theta [rad]), is taken from the measured first samples:

- theta: the first measured angle (an encoder's zero is arbitrary);
- i: the first measured current (voltage-driven logs with a current sensor), else 0;
- omega: the mean of the first few measured speeds; a start within noise of zero, or under 10 %
  of the log's speed range, is exactly at rest (the kernel's stick-slip test needs omega = 0
  exactly), and so is a constant reading while nothing drives the rotor (a sensor bias: an
  undriven rotor that turns slows down); a start clearly turning is a free parameter of the
  simulation-error fits (:func:`moving_start`), started there.
"""

from __future__ import annotations

import math

import numpy as np

#: samples averaged for the starting speed
HEAD = 5
#: a starting speed within this many standard errors of zero is a start at rest
REST_SIGMAS = 4.0
#: ... and so is one under this fraction of the log's speed range (99th percentile of |omega|):
#: it decays within one time constant and is not worth a parameter, and a speed derived from
#: the angle is least reliable at the log's edge (EMPS starts at 8 mm/s, 6.5 % of its range)
MOVING_FRACTION = 0.10


def _head(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x[:HEAD], float)
    return x[np.isfinite(x)]


def start_speed(log, sigma: float | None = None) -> float:
    """Measured speed at the first sample [rad/s]: 0 when it is within noise of rest."""
    if not log.has("omega"):
        return 0.0
    head = _head(log["omega"])
    if head.size == 0:
        return 0.0
    w0 = float(np.mean(head))
    if sigma is None:
        from pmdcid.io.derive import noise_std

        sigma = noise_std(np.asarray(log["omega"], float)[np.isfinite(log["omega"])])
    sd = max(float(sigma) if math.isfinite(sigma) else 0.0, 0.0) / math.sqrt(head.size)
    if "omega" in log.derived:
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
    """x0 = (i [A], omega [rad/s], theta [rad]) at the log's first sample (module docstring)."""
    i0 = 0.0
    if log.has("i") and log.drive == "v":
        head = _head(log["i"])
        i0 = float(head[0]) if head.size else 0.0
    th0 = 0.0
    if log.has("theta"):
        head = _head(log["theta"])
        th0 = float(head[0]) if head.size else 0.0
    return np.array([i0, start_speed(log, sigma_omega), th0])


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


__all__ = ["initial_state", "moving_start", "start_speed", "true_start"]
