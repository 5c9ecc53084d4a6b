"""A torque offset tau0 [N m] is an effect (``torque_offset``): the rule every stage that fits one
(fit-nonlinear, identify's joint fit, fit-inverse-dynamics, the closed-loop fit) writes it by.

Fitted where the speed moves both ways (:func:`.nonlinear_setup.both_directions`), tau0 is
written only where it passes the evidence every added effect meets in diagnose: its BIC
difference on the fit below -10 (``diagnose.settings.Rules.bic``), the Wald chi-square drop z^2
standing in for the refit without it. A 2-standard-error test wrote a false offset in one fit in
twenty, and more where the model lacks a friction term (docs/identification.md, "Torque-driven
rigs"); diagnose still tests ``torque_offset`` on held-out data.
"""

from __future__ import annotations

import math

#: the evidence every added effect meets, its BIC difference on the fit below this: diagnose's
#: ``Rules.bic`` default, and the rule a stage writes tau0 by (an offset is an effect)
OFFSET_BIC = -10.0
#: the note when a fitted tau0 falls short of :data:`OFFSET_BIC`
OFFSET_UNSHOWN = ("tau0 = {v:.3g} ± {se:.2g} {u} ({z:.1f} standard errors; ΔBIC ≈ {bic:+.0f}, not "
                  "below {rule:g}): these logs do not show a torque offset with the evidence an "
                  "effect needs, so it is not written (diagnose tests torque_offset on held-out "
                  "data; to show one, record motion in both directions at several levels)")


def offset_bic(value: float, stderr: float, ndata: int) -> float:
    """The BIC difference of a fitted torque offset ``value`` ± ``stderr`` [N m] on ``ndata``
    samples: -z^2 (the Wald chi-square drop, z = value / stderr) + ln(ndata) (its one parameter);
    +inf when the standard error is not finite or not positive (tau0 undetermined)."""
    if not (math.isfinite(stderr) and stderr > 0 and math.isfinite(value)):
        return math.inf
    return -(value / stderr) ** 2 + math.log(max(int(ndata), 2))


def offset_evident(value: float, stderr: float, ndata: int) -> bool:
    """True when a fitted tau0 passes the rule an effect needs (:data:`OFFSET_BIC`): two logs that
    each turn one way determine tau0 (it moves both ways), yet a 2-standard-error test writes
    a false offset in one fit in twenty, and any friction the model lacks (Stribeck's) shows as
    one; diagnose then tests the offset on held-out data."""
    return offset_bic(value, stderr, ndata) < OFFSET_BIC


def offset_note(value: float, stderr: float, unit: str, ndata: int) -> str:
    """The note when a fitted tau0 is not :func:`offset_evident`."""
    z = value / stderr if stderr and math.isfinite(stderr) else math.nan
    return OFFSET_UNSHOWN.format(v=value, se=stderr, u=unit, z=abs(z),
                                 bic=offset_bic(value, stderr, ndata), rule=OFFSET_BIC)
