"""The one owner of parameter declarations: :class:`ParamSpec` and the base parameters.

Each parameter is declared once, with its unit, meaning, the value that switches it off
(``neutral``) and its bounds: the paper's base parameters here, each effect's own in its
catalogue record (:mod:`pmdcid.model.effects`, whose ``param_spec``, ``unit_of`` and
``bounds_of`` answer for any name). The kernel's parameter vector (:mod:`pmdcid.simulate.layout`)
is checked against these declarations at import: a parameter without a slot is an error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ParamSpec:
    """Declaration of one parameter: name, unit, meaning, the value that switches it off, bounds."""

    name: str
    unit: str
    doc: str
    neutral: float = 0.0
    lower: float = -math.inf
    upper: float = math.inf

    def spanned(self, value: float, stderr: float) -> bool:
        """Whether ``value`` +- :data:`RANGE_SE` x ``stderr`` covers this parameter's whole
        range [lower, upper] (:func:`spans_range`)."""
        return spans_range(value, stderr, self.lower, self.upper)


#: standard errors either side of a bounded parameter's value that, spanning its whole range,
#: leave nothing the logs said about it (a 95 % interval wider than every value it may take)
RANGE_SE = 2.0


def spans_range(value: float, stderr: float, lower: float, upper: float) -> bool:
    """Whether the interval ``value`` +- :data:`RANGE_SE` ``stderr`` [unit] covers the whole
    range [``lower``, ``upper``] [unit] of a parameter bounded on both sides: its standard error
    then carries no information from the logs (a linearisation of a cost flat across the range:
    a lumped model's back-EMF share 0.0001 +- 0.58 on [0, 1]) and is not one to print. False for
    a range open on either side, or a standard error that is not a finite number."""
    return (math.isfinite(lower) and math.isfinite(upper) and math.isfinite(stderr)
            and value - RANGE_SE * stderr <= lower and value + RANGE_SE * stderr >= upper)


#: a value within this fraction of its standard error of a finite bound sits at the bound: the
#: fit stopped there, and the curvature it was read from is one-sided
AT_BOUND_SE = 0.01


def bound_reach(value: float, stderr: float, lower: float,
                upper: float) -> tuple[float, float] | None:
    """[unit] (the bound, the value :data:`RANGE_SE` standard errors into the range) for a
    ``value`` at a finite bound (:data:`AT_BOUND_SE`) with a finite positive ``stderr``: a
    fit that ends at 0 friction prints no ``4e-14 +- 0.0098`` (half of that interval lies where
    the parameter cannot go), but the interval the logs leave it in. None otherwise."""
    if not (math.isfinite(stderr) and stderr > 0 and math.isfinite(value)):
        return None
    if math.isfinite(lower) and value - lower <= AT_BOUND_SE * stderr:
        return lower, min(value + RANGE_SE * stderr, upper)
    if math.isfinite(upper) and upper - value <= AT_BOUND_SE * stderr:
        return max(value - RANGE_SE * stderr, lower), upper
    return None


def bound_words(bound: float) -> str:
    """The words a parameter at its bound (:func:`bound_reach`) carries with its interval."""
    return (f"at its bound {bound:g}: the fit stops there, where its curvature gives no "
            "standard error; the interval reaches two of it into the range")


def range_words(lower: float, upper: float, unit: str) -> str:
    """The words a parameter carries in place of a standard error that spans its whole range
    (:func:`spans_range`)."""
    rng = f"[{lower:g}, {upper:g}]" + (f" {unit}" if unit and unit != "1" else "")
    return (f"not determined by these logs: bounded only by its range {rng} (+-2 standard "
            "errors of the fit would span all of it)")


BASE_PARAMS: dict[str, ParamSpec] = {
    p.name: p
    for p in [
        ParamSpec("R", "ohm", "armature resistance", math.nan, 1e-6, 1e6),
        ParamSpec("L", "H", "armature inductance (0: the current follows the voltage at once)",
                  math.nan, 0.0, 10.0),
        ParamSpec("km", "N m/A", "torque constant", math.nan, 1e-9, 1e3),
        ParamSpec("J", "kg m^2", "rotor inertia (kg for a linear axis)", math.nan, 1e-12, 1e6),
        ParamSpec("b", "N m s/rad", "linear viscous friction, Coulomb lumped in (paper)", 0.0,
                  0.0, 1e6),
        ParamSpec("bv", "N m s/rad", "viscous friction coefficient", 0.0, 0.0, 1e6),
        ParamSpec("bc", "N m", "Coulomb friction level", 0.0, 0.0, 1e6),
        ParamSpec("dz", "N m", "torque break point of the hard dead zone", 0.0, 0.0, 1e6),
        ParamSpec("dz_slope", "1", "slope k-bar of the hard dead zone (paper eq. 7)", 1.0, 0.0,
                  10.0),
        ParamSpec("dz_offset", "N m", "jump k-hat of the hard dead zone (paper eq. 7)", 0.0,
                  -1e6, 1e6),
        # a lumped (per-volt) model's electrical side (pmdcid/model/lumped.py); not kernel slots
        ParamSpec("tau_e", "s", "electrical time constant L/R of a lumped (per-volt) model "
                  "(0: none, the torque follows the voltage at once)", 0.0, 0.0, 1.0),
        ParamSpec("ke_share", "1", "share of a lumped model's viscous damping bv that is "
                  "back-EMF (the rest is mechanical viscous friction)", 1.0, 0.0, 1.0),
    ]
}

__all__ = ["AT_BOUND_SE", "BASE_PARAMS", "RANGE_SE", "ParamSpec", "bound_reach", "bound_words",
           "range_words", "spans_range"]
