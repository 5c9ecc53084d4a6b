"""How finely the kernel steps, and the bound on its work: small pure functions on the flat
parameter vector (:data:`pmdcid.simulate.layout.NAMES`), kept apart from the compiled loops of
:mod:`pmdcid.simulate.kernel`.
"""

from __future__ import annotations

import math
from contextlib import contextmanager

import numpy as np

from pmdcid.errors import ModelError
from pmdcid.simulate.layout import BV, KE, KM, SIGMA0, SIGMA1, J, R

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


#: most internal steps a sample the mechanical time constant asks for (:data:`STEPS_PER_TAU`):
#: a rotor whose J/bv is under a fifth of a sample follows its torque within the sample, the
#: kernel's linear step is exact at any length and finds each stop inside its step, so a finer
#: step moves the sampled speed by less than a 256th of a sample's transient. Without the cap a
#: fit that tried J near 0 on a slow ramp took minutes, or stopped on :data:`MAX_STEPS`
#: (fra233-g04's ramp_3.csv alone, 2 kHz: 2400 steps in each of 64 parts a sample, and
#: identify refused, blaming the time unit). The 1 ms bound and LuGre's are not capped
MAX_MECH_SUBSTEPS = 256


def choose_substeps(dt: float, p: np.ndarray, h_max: float | None = None) -> int:
    """Internal steps per sample: h <= :func:`max_step` (its J/bv part at most
    :data:`MAX_MECH_SUBSTEPS` a sample) unless ``h_max`` [s] is given."""
    if h_max is not None:
        return substeps_for(dt, h_max)
    n = min(substeps_for(dt, max_step(p)), max(MAX_MECH_SUBSTEPS, substeps_for(dt, 1e-3)))
    if p[SIGMA0] > 0:
        n = max(n, substeps_for(dt, lugre_step(p)))
    return n


def substeps_for(dt: float, h_max: float) -> int:
    """Fewest internal steps of at most h_max [s] in a sample period dt [s] (at least 1)."""
    return max(1, int(math.ceil(dt / h_max - 1e-9)))


def mechanical_damping(p) -> float:
    """Damping of the rotor's speed [N m s/rad]: bv plus the back-EMF's km ke / R."""
    damping = p[BV]
    if p[R] > 0:
        damping += p[KM] * p[KE] / p[R]
    return damping


def max_step(p) -> float:
    """Largest internal step [s]: min(1 ms, tau_mech / 50), tau_mech = J / (bv + km ke / R)
    [s], the back-EMF's damping included. With LuGre on, also :func:`lugre_step` (its spring
    and micro-damping are held over a step)."""
    h_max = 1e-3
    damping = mechanical_damping(p)
    if damping > 0 and p[J] > 0:
        h_max = min(h_max, p[J] / damping / STEPS_PER_TAU)
    if p[SIGMA0] > 0:
        h_max = min(h_max, lugre_step(p))
    return h_max


#: internal steps per radian of the bristles' presliding oscillation sqrt(sigma0/J), and per
#: micro-damping time J/sigma1: the spring force sigma0 z and sigma1's a z part are held over a
#: step, stable for h sqrt(sigma0/J) < 2 and h sigma1/J < 1; 20 keeps the presliding period's
#: error near (h w_n)^2/24 = 1e-4
LUGRE_STEPS = 20.0


def lugre_step(p: np.ndarray) -> float:
    """Largest internal step [s] for LuGre: sqrt(J/sigma0)/20 and J/(20 sigma1). The bristle
    deflection's own time constant g/(sigma0 |omega|) needs no bound: z is stepped exactly."""
    h = math.sqrt(p[J] / p[SIGMA0]) / LUGRE_STEPS if p[J] > 0 else math.inf
    if p[SIGMA1] > 0 and p[J] > 0:
        h = min(h, p[J] / p[SIGMA1] / LUGRE_STEPS)
    return h


def check_work(n: int, dt: float, nsub: int, p: np.ndarray) -> None:
    """Raise :class:`WorkBoundError` when ``n`` samples of ``nsub`` substeps exceed the bound."""
    steps = float(n) * float(nsub)
    if steps <= MAX_STEPS:
        return
    if p[SIGMA0] > 0 and lugre_step(p) < dt / float(nsub) * 1.5:
        raise WorkBoundError(
            f"the simulation would take {steps:.2g} internal steps (limit {MAX_STEPS:.0e}): "
            f"LuGre's bristles (sigma0 = {p[SIGMA0]:.3g} N m/rad, sigma1 = {p[SIGMA1]:.3g} "
            f"N m s/rad) need steps of {lugre_step(p):.2g} s: check sigma0, sigma1 and J")
    damping = mechanical_damping(p)
    tau = p[J] / damping if damping > 0 else math.inf
    raise WorkBoundError(
        f"the simulation would take {steps:.2g} internal steps ({n} samples x {float(nsub):.2g} "
        f"substeps; limit {MAX_STEPS:.0e}): a sample period of {dt:.3g} s is "
        f"{dt / tau:.2g} x the time constant J/(bv+km^2/R) = {tau:.3g} s: check J (value, unit) "
        "or the time unit (t in ms or us? -c t=COLUMN*ms)")


__all__ = ["LUGRE_STEPS", "MAX_MECH_SUBSTEPS", "MAX_STEPS", "STEPS_PER_TAU", "WorkBoundError",
           "bounded_for", "check_work", "choose_substeps", "lugre_step", "max_step",
           "mechanical_damping", "substeps_for"]
