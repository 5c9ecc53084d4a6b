"""Candidate input profiles of an identification plan (zero-order held at the rig's rate).

Each generator returns one *unit* of a profile (``u`` at instants ``k/rate``): a plan repeats the
unit as many times as its share of the recording time. Amplitudes are inputs in the drive's unit:
volts for a voltage-driven rig, N m (or the lumped model's per-volt unit) for a torque-driven one.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: kinds of candidate profiles, what each is for
PURPOSES = {
    "blocked": "blocked-rotor voltage step: R and L from the current's rise (rotor held)",
    "steps": "free steps in both directions (0, +A, 0, -A): J from the transients, bv from the "
             "plateaus, bc from the difference between the directions",
    "triangle": "slow triangle through zero speed: bc and bv across the speed range, the dead "
                "zone where the rotor stops and starts",
    "staircase": "staircase bracketing the breakaway input up and down, both directions: "
                 "breakaway (dz or bc) and stopping (bc) separately",
    "levels": "levels just above the breakaway and at the full input, both directions: bc "
              "from slow sliding (where viscous friction is small) against bv from fast",
    "slow_triangle": "slow triangle to 3x the breakaway input: the dead zone from where the "
                     "rotor starts and stops, many times",
    "prbs": "pseudo-random binary sequence between -A and +A: J (and a sensor delay) from fast "
            "reversals",
    "ramp": "slow ramp up and down, both directions: where the rotor starts and stops",
    "small_steps": "small steps up and back to rest: the mechanical time constant, a first J",
}


@dataclass
class Profile:
    """One profile: ``name`` (file stem), ``kind`` (key of :data:`PURPOSES`), input ``u`` at
    instants ``t`` [s] (V or N m), ``blocked`` for a blocked-rotor profile, ``units`` repeats
    of its unit (the last one may be cut short)."""

    name: str
    kind: str
    t: np.ndarray
    u: np.ndarray
    blocked: bool = False
    units: float = 1.0
    meta: dict[str, str] = field(default_factory=dict)

    @property
    def seconds(self) -> float:
        return len(self.t) / rate_of(self.t)

    @property
    def purpose(self) -> str:
        return PURPOSES[self.kind]


def rate_of(t: np.ndarray) -> float:
    """Sampling rate [Hz] of uniformly spaced instants."""
    return 1.0 / float(t[1] - t[0]) if len(t) > 1 else 1.0


def instants(seconds: float, rate: float) -> np.ndarray:
    """``t`` [s] of ``seconds`` of samples at ``rate`` [Hz] (at least 2 samples)."""
    return np.arange(max(int(round(seconds * rate)), 2)) / rate


def hold(levels, seconds: float, rate: float) -> np.ndarray:
    """Each of ``levels`` held ``seconds`` (at least one sample) at ``rate`` [Hz]."""
    n = max(int(round(seconds * rate)), 1)
    return np.repeat(np.asarray(levels, float), n)


def blocked_step(amp: float, te: float, rate: float, longer: float = 1.0) -> np.ndarray:
    """One step 0 -> amp with the rotor held, onset after 10 electrical time constants ``te``
    [s], held ``longer`` x 30 ``te`` (at least 20 samples each): a longer hold averages the
    settled current (R) over more samples."""
    pre = max(10 * te, 20 / rate)
    return np.concatenate([hold([0.0], pre, rate),
                           hold([amp], longer * max(30 * te, 40 / rate), rate)])


def free_steps(amp: float, tm: float, rate: float) -> np.ndarray:
    """0, +amp, 0, -amp, each held 5 mechanical time constants ``tm`` [s] (at least 0.2 s)."""
    return hold([0.0, amp, 0.0, -amp], max(5 * tm, 0.2), rate)


def triangle(amp: float, period: float, rate: float) -> np.ndarray:
    """One ``period`` [s] of a triangle 0 -> +amp -> -amp -> 0."""
    t = instants(period, rate)
    phase = (t / period + 0.25) % 1.0
    return amp * (1.0 - 4.0 * np.abs(phase - 0.5))


#: staircase levels, fractions of the breakaway input: none at 1 (a level exactly at the
#: breakaway is a knife edge, whether the rotor moves at all flips with the smallest change)
STAIR = (0.6, 0.8, 0.93, 1.07, 1.2, 1.4, 1.7, 2.0, 1.7, 1.4, 1.2, 1.07, 0.93, 0.8, 0.6, 0.0)


def staircase(breakaway: float, amp: float, tm: float, rate: float) -> np.ndarray:
    """Levels bracketing the ``breakaway`` input up then down, positive then negative, each held
    3 ``tm`` (at least 0.1 s), clipped to ``amp``."""
    lv = np.minimum(np.array(STAIR) * breakaway, amp)
    return hold(np.concatenate([lv, -lv]), max(3 * tm, 0.1), rate)


#: low level of the levels profile, multiple of the breakaway input
LEVEL_LOW = 1.2


def levels(breakaway: float, amp: float, tm: float, rate: float) -> np.ndarray:
    """LEVEL_LOW x ``breakaway``, ``amp``, then the same negative, each held 6 ``tm`` [s]
    (at least 0.2 s): slow sliding, where the Coulomb friction is most of the torque, and fast
    sliding, where the viscous friction is."""
    lo = min(LEVEL_LOW * breakaway, amp)
    return hold([lo, amp, -lo, -amp], max(6 * tm, 0.2), rate)


def slow_triangle(breakaway: float, amp: float, tm: float, rate: float) -> np.ndarray:
    """A triangle to min(3 ``breakaway``, ``amp``) of period 400 ``tm`` (at least 10 s)."""
    return triangle(min(3 * breakaway, amp), max(400 * tm, 10.0), rate)


def prbs(amp: float, tm: float, rate: float, order: int = 7, seed: int = 1) -> np.ndarray:
    """Maximum-length binary sequence (LFSR, ``2**order - 1`` bits) between -amp and +amp, bit
    length a quarter of the mechanical time constant ``tm`` (at least 2 samples): reversals
    before the speed settles carry the most information on J and, through the decelerations,
    on the Coulomb friction."""
    taps = {5: (5, 3), 6: (6, 5), 7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5)}[order]
    state = [(seed >> k) & 1 or (k == 0) for k in range(order)]
    bits = []
    for _ in range(2**order - 1):
        bits.append(state[-1])
        fb = 0
        for tp in taps:
            fb ^= state[tp - 1]
        state = [fb] + state[:-1]
    return hold(amp * (2.0 * np.array(bits, float) - 1.0), max(0.25 * tm, 2 / rate), rate)


def ramp(amp: float, seconds: float, rate: float) -> np.ndarray:
    """0 -> +amp -> 0 -> -amp -> 0 in straight lines over ``seconds`` [s]."""
    t = instants(seconds, rate)
    phase = (t / seconds + 0.25) % 1.0
    return amp * (1.0 - 4.0 * np.abs(phase - 0.5))


def small_steps(amps, seconds: float, rate: float) -> np.ndarray:
    """Rest, then each amplitude in ``amps`` and rest again, all held ``seconds`` [s]; then the
    negatives. The rest comes first: a step needs its level before recorded (fit-mechanical
    finds a step by the change, and the rotor's starting state is measured there)."""
    lv = [x for a in amps for x in (a, 0.0)]
    return hold([0.0] + lv + [-x for x in lv], seconds, rate)


def repeat(u: np.ndarray, n: int) -> np.ndarray:
    """``n`` samples of a profile unit repeated one after the other (the last cut short)."""
    return np.tile(u, int(np.ceil(n / len(u))))[:n]


def make(name: str, kind: str, u: np.ndarray, rate: float, blocked: bool = False,
         seconds: float | None = None) -> Profile:
    """A :class:`Profile` of ``seconds`` [s] (default one unit) of ``u`` repeated at ``rate``."""
    n = len(u) if seconds is None else max(int(seconds * rate + 1e-9), 2)
    uu = repeat(u, n)
    return Profile(name, kind, np.arange(n) / rate, uu, blocked, n / len(u))


def seconds_of(u: np.ndarray, rate: float) -> float:
    return len(u) / rate


__all__ = ["PURPOSES", "Profile", "blocked_step", "free_steps", "hold", "instants", "make",
           "prbs", "ramp", "rate_of", "repeat", "seconds_of", "small_steps", "staircase",
           "triangle"]
