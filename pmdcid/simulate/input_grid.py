"""Drive effects applied to the input before the kernel: the command applied late.

A host-paced loop (a PC or a Simulink model streaming over USB/serial to a microcontroller that
sets the PWM) applies each logged command some milliseconds after its time stamp: the input is
delayed, so every state, the current included, follows it late (``input_delay``). The logged
input is zero-order held over each sample period; delayed by ``latency`` seconds, it switches
inside the periods unless the latency is a multiple of the sample period.

The kernel holds its input over each sample, so the late input is built on a grid ``q`` times
finer (``q`` at least :data:`MIN_PARTS` and at least the kernel's internal steps per sample, so
the simulation takes no longer steps than it would without the delay), each fine interval
holding the *exact average* of the delayed input over it (from the input's running integral).
A latency that is a multiple of dt/q is therefore simulated exactly (to rounding, like the kernel's
linear part); any other is exact at every fine boundary but one per switch, where the switch is
smeared over one fine interval (its mean kept: a state error second order in dt/q over the time
constants). The simulated states depend continuously (piecewise linearly) on the latency, which
a finite-difference Jacobian needs.

The same fine grid serves an input read *between* its samples (``ramp``): a log of a continuously
varying command (a ramp or sine generated faster than it is logged) does not hold each value for
a whole period; read as held it is applied half a sample late, which a fit turns into a wrong
inertia when the sample period is not small against J/bv. :func:`ramp_input` blends the held
reading (ramp = 0, the contract's zero-order hold) with the linear one (ramp = 1, straight to the
next sample), again as exact averages over the fine intervals.
"""

from __future__ import annotations

import math

import numpy as np

#: fewest fine intervals per sample period for a late input (resolution dt / MIN_PARTS)
MIN_PARTS = 8
#: most fine intervals per sample period: a stiffer model takes :func:`inner_steps` internal
#: steps inside each (a fit that tried J near 0 on a 2 kHz ramp asked for 39019 a sample, and
#: the fine input and its states for 8001 samples took 18 GB before the kernel ran)
MAX_PARTS = 64


def parts_for(nsub: int) -> int:
    """Fine intervals per sample for a late input: at least :data:`MIN_PARTS` and ``nsub``, at
    most :data:`MAX_PARTS` (the rest as :func:`inner_steps`)."""
    return min(max(MIN_PARTS, int(nsub)), MAX_PARTS)


def inner_steps(nsub: int, q: int) -> int:
    """The kernel's internal steps in each of the ``q`` fine intervals of a sample, so that its
    steps are no longer than with ``nsub`` a sample on the held input."""
    return max(1, -(-int(nsub) // int(q)))


def late_input(u: np.ndarray, dt: float, latency: float, q: int) -> np.ndarray:
    """The zero-order-held input ``u`` (sampled at ``dt`` [s]) applied ``latency`` [s] late, as
    the averages over ``q`` fine intervals per sample (length n*q). Before the first sample the
    input is ``u[0]`` (the state the log starts in)."""
    u = np.asarray(u, dtype=float)
    n = len(u)
    if latency < 0 or not math.isfinite(latency):
        raise ValueError(f"latency must be finite and >= 0, got {latency}")
    # running integral U(s) of the held input at its knots s = -(pad) .. n*dt
    pad = (math.floor(latency / dt) + 1) * dt
    knots = np.concatenate(([-pad], np.arange(n + 1) * dt))
    U = np.concatenate(([-u[0] * pad], [0.0], np.cumsum(u) * dt))
    edges = np.arange(n * q + 1) * (dt / q) - latency
    cum = np.interp(edges, knots, U)
    return np.diff(cum) / (dt / q)


def ramp_input(u: np.ndarray, dt: float, latency: float, ramp: float, q: int) -> np.ndarray:
    """The input ``u`` (sampled at ``dt`` [s]) read between samples as ``(1 - ramp)`` x held
    plus ``ramp`` x linear toward the next sample [dimensionless blend], applied ``latency``
    [s] late, as the exact averages over ``q`` fine intervals per sample (length n*q). Before
    the first sample the input is ``u[0]``; after the last it is held at ``u[-1]``."""
    u = np.asarray(u, dtype=float)
    n = len(u)
    if latency < 0 or not math.isfinite(latency) or not math.isfinite(ramp):
        raise ValueError(f"latency must be finite and >= 0 and ramp finite, got {latency}, {ramp}")
    slope = ramp * (np.append(u[1:], u[-1]) - u) / dt  # [unit/s] within each sample period
    if latency == 0.0:  # fine intervals inside the samples: each average is the midpoint's value
        mids = (np.arange(q) + 0.5) * (dt / q)
        return (u[:, None] + slope[:, None] * mids).ravel()
    # running integral U(s) of the applied input: piecewise quadratic, exact at every edge
    whole = np.concatenate(([0.0], np.cumsum(u * dt + 0.5 * slope * dt * dt)))
    edges = np.arange(n * q + 1) * (dt / q) - latency
    k = np.clip(np.floor(edges / dt).astype(np.int64), 0, n - 1)
    s = edges - k * dt
    cum = whole[k] + u[k] * s + 0.5 * slope[k] * s * s
    before = edges < 0.0
    cum[before] = u[0] * edges[before]
    after = edges > n * dt
    cum[after] = whole[n] + u[-1] * (edges[after] - n * dt)
    return np.diff(cum) / (dt / q)


#: the last inputs built on the fine grid: key -> (the logged input's copy, the fine input)
_BUILT: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
#: how many bytes of them are kept: a fit's logs, each simulated at every Jacobian column
_KEPT_BYTES = 128 * 2**20


def fine_input(u: np.ndarray, dt: float, latency: float, ramp: float | None,
               q: int) -> np.ndarray:
    """The input on the fine grid: :func:`late_input` (``ramp`` None) or :func:`ramp_input`.

    A fit simulates each log at every evaluation with the same reading (only a fitted latency
    moves it), so the last few are kept, found by the logged array's identity and the reading
    and used only while the array still holds the values they were built from (compared in
    full: an array changed in place, or a new one at a freed one's address, is built afresh).
    The result is read-only: the kernel only reads its input."""
    u = np.asarray(u, dtype=float)
    key = (id(u), len(u), float(dt), float(latency), ramp, int(q))
    hit = _BUILT.get(key)
    if hit is not None and np.array_equal(hit[0], u):
        return hit[1]
    fine = late_input(u, dt, latency, q) if ramp is None else ramp_input(u, dt, latency, ramp, q)
    fine.flags.writeable = False
    size = fine.nbytes + u.nbytes
    while _BUILT and size + _kept_bytes() > _KEPT_BYTES:
        _BUILT.pop(next(iter(list(_BUILT))), None)  # the oldest (a thread may pop it first)
    if size <= _KEPT_BYTES:
        _BUILT[key] = (u.copy(), fine)
    return fine


def _kept_bytes() -> int:
    return sum(a.nbytes + f.nbytes for a, f in list(_BUILT.values()))


def read_input(u: np.ndarray, dt: float, nsub: int, latency: float, ramp: float | None,
               within: np.ndarray | None = None):
    """The input the kernel steps: (input, its step [s], internal steps per input step, fine
    intervals per sample q; the states at every q-th step are the samples').

    ``u`` itself when it is held on time (q = 1); late or read between samples, on the fine grid
    (:func:`fine_input`); ``within``: the input inside each sample as ``len(within) // len(u)``
    means per sample (a loop-timed log's input held from its own instants,
    :meth:`pmdcid.io.Log.input_within`), stepped as it is, applied ``latency`` late on its own
    grid. A ramp reading is a reading of ``u`` and takes ``u``."""
    if within is not None and ramp is None:
        q = len(within) // len(u)
        if latency > 0.0:
            within = fine_input(within, dt / q, latency, None, 1)
        return within, dt / q, inner_steps(nsub, q), q
    if latency <= 0.0 and ramp is None:
        return u, dt, nsub, 1
    q = parts_for(nsub)
    return fine_input(u, dt, latency, ramp, q), dt / q, inner_steps(nsub, q), q


__all__ = ["MAX_PARTS", "MIN_PARTS", "fine_input", "inner_steps", "late_input", "parts_for",
           "ramp_input", "read_input"]
