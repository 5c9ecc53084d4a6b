"""How a slowly logged input varied between its samples: held, or straight to the next sample.

docs/io.md reads ``v`` and ``tau`` as held between samples (zero-order hold). A command that
varies continuously (a ramp, a sine generated faster than it is logged) is not: read as held, it
acts half a sample late, and when the sample period is not small against the mechanical time
constant J/bv a fit turns that lag into a wrong inertia with a small standard error
(docs/identification.md: J -63 % at 10 Hz). Nothing but the fit can tell a drive that holds each
value (a slow digital loop) from a continuous command logged slowly, so when it matters
(:func:`~pmdcid.identify.identifiability.hold_matters`) fit-nonlinear reads the input as a blend
``ramp`` (0 held, 1 linear between samples; :func:`pmdcid.simulate.input_grid.ramp_input`) and
chooses it by a **profile**: the whole local fit at :data:`RAMPS`, a parabola through the
chi-squares, its minimum and the width where the chi-square rises by the reduced chi-square.
Why a profile and not one more free parameter: the cost in ``ramp`` is smooth only over tenths
(the stick-slip events move by fractions of a fine step), and a local solver stopped 6 standard
errors from the profile's minimum on an exactly held 33 Hz log. The inertia's standard error
then carries the part of the ramp the data leave open: hypot(se_J, dJ/dramp x se_ramp).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: the readings fitted: held, three blends, linear
RAMPS = (0.0, 0.25, 0.5, 0.75, 1.0)
#: the words beside a ramp the profile leaves open (its uniform spread still widens J's error)
RAMP_CAVEAT = ("not determined by these logs: how the input varied between samples; log "
               "faster, or log the drive's own updates")


@dataclass(frozen=True)
class RampProfile:
    """The profile's result: ``value`` and ``stderr`` of the ramp [dimensionless], the chi-square
    at each of :data:`RAMPS`, and the slope of the fitted inertia in the ramp [kg m^2]."""

    value: float
    stderr: float
    chisqr: tuple[float, ...]
    dJ: float

    def inertia_stderr(self, se_J: float) -> float:
        """J's standard error [kg m^2] with the ramp's uncertainty carried over."""
        return math.hypot(se_J, self.dJ * self.stderr)

    def estimates(self, J=None) -> dict:
        """``ramp`` and, given the fit's J (an Estimate), J with the ramp's share of its error."""
        from pmdcid.fit.results import Estimate, bounded

        if self.stderr >= (RAMPS[-1] - RAMPS[0]) / math.sqrt(12.0):  # the profile is flat
            out = {"ramp": bounded("ramp", RAMPS[0], RAMPS[-1], "", RAMP_CAVEAT, self.value)}
        else:
            out = {"ramp": Estimate("ramp", self.value, self.stderr, "")}
        if J is not None:
            out["J"] = Estimate("J", J.value, self.inertia_stderr(J.stderr), J.unit, J.vary)
        return out


def parabola_minimum(x: np.ndarray, y: np.ndarray, scale: float) -> tuple[float, float]:
    """(minimum, half-width where y rises by ``scale``) of the parabola through the lowest point
    of (x, y) and its two neighbours (the end three at an end), the minimum kept within them.
    A flat or concave triple gives the lowest point and the whole range over sqrt(12) (a
    uniform spread). Local, not a least-squares parabola over every point: a profile that drops
    steeply from one end is not a parabola, and such a fit put the minimum 12 standard errors
    from the lowest point."""
    k = min(max(int(np.argmin(y)), 1), len(x) - 2)
    xs, ys = x[k - 1:k + 2], y[k - 1:k + 2]
    a, b, _ = np.polyfit(xs, ys, 2)
    spread = float(x[-1] - x[0]) / math.sqrt(12.0)
    if not a > 0:
        return float(x[int(np.argmin(y))]), spread
    return (min(max(-b / (2 * a), float(xs[0])), float(xs[-1])),
            min(math.sqrt(max(scale, 1e-12) / a), spread))


def roughness(x: np.ndarray, y: np.ndarray) -> float:
    """The scatter of ``y`` about the least-squares parabola through all of (x, y): the rms
    residual over the len(x) - 3 degrees of freedom (0 with three points or fewer). Each of the
    profile's points is a local fit that stops in some dip of a cost made rough by the dead
    zone's events: measured on the paper's motor with a 10 Hz triangle (a lumped model,
    tests/system/test_diagnose.py), fits at neighbouring ramps stopped 20-160 chi-square units
    off a smooth profile, and read with a rise of 1 the ramp's standard error came out 0.012
    at 25 standard errors from the truth."""
    if len(x) <= 3:
        return 0.0
    r = y - np.polyval(np.polyfit(x, y, 2), x)
    return float(math.sqrt(np.sum(r ** 2) / (len(x) - 3)))


def ramp_profile(fit_at: Callable[[float], tuple[float, float]], redchi: float,
                 rough: bool = False) -> RampProfile:
    """Profile of the ramp: ``fit_at(r)`` runs the local fit with the input read at ramp ``r``
    and returns (chi-square, fitted J [kg m^2]); ``redchi`` scales the width (the noise
    weights' honesty), and, ``rough`` (the local fits stop in dips of a rough cost: a lumped
    model with an electrical lag), the profile's own scatter (:func:`roughness`) where it is
    larger. Not otherwise: a smooth profile that drops steeply from one end is no parabola
    either (on the paper's 10 Hz triangle with km known its scatter about one was 85
    chi-square units where its points lay within 10 of the lowest from ramp 0.5 to 1).
    J's slope in the ramp is taken between the neighbours of the lowest point, where the
    minimum lies."""
    xs = np.array(RAMPS)
    got = [fit_at(float(r)) for r in xs]
    chi = np.array([c for c, _ in got])
    js = np.array([j for _, j in got])
    scatter = roughness(xs, chi) if rough else 0.0
    value, se = parabola_minimum(xs, chi, max(redchi, 1.0, scatter))
    k = min(max(int(np.argmin(chi)), 1), len(xs) - 2)
    dJ = float((js[k + 1] - js[k - 1]) / (xs[k + 1] - xs[k - 1]))
    return RampProfile(value, se, tuple(float(c) for c in chi), dJ)


def hold_profile(logs, start: dict, free, fit_at) -> RampProfile | None:
    """The ramp's profile when some log's input reading moves J (``start``: the fit's starting
    J [kg m^2] and bv [N m s/rad]; ``free``: the fitted names; a free ``tau_e``, a lumped
    model's lag, makes the cost rough: :func:`ramp_profile`), else None."""
    from pmdcid.identify.identifiability import hold_matters

    if "J" not in free or not any(hold_matters(lg, start["J"], start.get("bv", math.nan))
                                  for lg in logs):
        return None
    return ramp_profile(fit_at, 1.0, rough="tau_e" in free)


__all__ = ["RAMPS", "RampProfile", "hold_profile", "parabola_minimum", "ramp_profile",
           "roughness"]
