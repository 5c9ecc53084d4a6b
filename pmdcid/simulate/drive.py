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
"""

from __future__ import annotations

import math

import numpy as np

#: fewest fine intervals per sample period for a late input (resolution dt / MIN_PARTS)
MIN_PARTS = 8


def parts_for(nsub: int) -> int:
    """Fine intervals per sample for a late input: at least :data:`MIN_PARTS` and ``nsub``."""
    return max(MIN_PARTS, int(nsub))


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


__all__ = ["MIN_PARTS", "late_input", "parts_for"]
