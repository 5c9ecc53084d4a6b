"""Can the held-out data test an effect at all, and do they confirm it?

A held-out gain is evidence for an effect only where the held-out data could have told the
effect from a change of the parameters the model already has. One step log split in time holds
out its steady tail: a sensor delay changes nothing there, and a quadratic drag or a friction
curve changes only the speed's level, which a new viscous or Coulomb friction changes as well.
Such a held-out "gain" says the effect re-balanced the base parameters, not that it exists.

The test, linearised at the candidate's refit (values ``fo``, effect switched on):

- ``d``: the effect's own change of the held-out residual (effect on minus effect off, the
  other parameters as refitted), weighted by the noise (each sample one unit of chi-square);
- ``B``: the held-out sensitivities of the free base parameters that can stand in for the
  effect (``Effect.interacts``: bv for a drag law, bc for a load torque, bc and bv for a speed
  bias; none for a delay, whose signature needs edges or reversals to show at all);
- *distinct* = ``|P d|^2``, ``P`` projecting out the columns of ``B``: the chi-square by which
  the held-out data can tell the effect, at its fitted size, from any re-adjustment of the
  others. Below ``floor`` the effect is *not testable with these logs*.
- *confirmed* = ``|P r_off|^2 - |P r_on|^2`` (``r``: the held-out residuals with the effect off
  and on): how much of that distinct part the held-out data actually bear out. A real effect
  gives about *distinct*; a spurious one about zero or less. The rule asks for half.

Cost: one held-out simulation per free parameter and one with the effect off.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.model import EFFECTS
from pmdcid.runtime.cpus import pmap

#: relative step of a parameter's held-out sensitivity column
STEP = 0.05
#: share of the distinct part the held-out data must bear out
CONFIRM_SHARE = 0.5


@dataclass(frozen=True)
class HeldoutTest:
    """What the held-out data can say about one effect (chi-square units, noise-weighted)."""

    distinct: float  # chi-square that tells the effect from the other parameters
    confirmed: float  # part of it the held-out data bear out
    floor: float  # the least distinct chi-square that counts as a test

    @property
    def testable(self) -> bool:
        return self.distinct >= self.floor

    @property
    def confirms(self) -> bool:
        return self.confirmed >= max(CONFIRM_SHARE * self.distinct, self.floor)


def _step(name: str, value: float, torque_scale: float) -> float:
    if value != 0.0 and math.isfinite(value):
        return STEP * abs(value)
    return STEP * torque_scale if name in ("bc", "dz", "tau0", "fs") else 0.0


def _project_out(b: np.ndarray | None, y: np.ndarray) -> np.ndarray:
    """``y`` minus its least-squares projection on the columns of ``b``."""
    if b is None or b.shape[1] == 0:
        return y
    coef, *_ = np.linalg.lstsq(b, y, rcond=None)
    return y - b @ coef


def heldout_test(problem, values: dict[str, float], effect: str, others: list[str],
                 torque_scale: float, floor: float) -> HeldoutTest | None:
    """The held-out test of ``effect`` at ``values`` (its refit), the parameters ``others``
    free to re-adjust; None when nothing is held out."""
    if problem.count("held") == 0:
        return HeldoutTest(0.0, 0.0, floor)
    off = {**values, **{p.name: p.neutral for p in EFFECTS[effect].params
                        if p.name not in EFFECTS[effect].held}}

    def resid(v: dict[str, float]) -> np.ndarray:
        return problem.weighted(problem.simulate_all(v, "held"), "held")

    r_on = resid(values)
    r_off = resid(off)
    steps = [(p, _step(p, values.get(p, 0.0), torque_scale)) for p in others]
    steps = [(p, h) for p, h in steps if h > 0]
    cols = pmap(lambda ph: resid({**values, ph[0]: values[ph[0]] + ph[1]}) - r_on, steps)
    cols = [c for c in cols if np.all(np.isfinite(c)) and np.any(c)]
    b = np.column_stack(cols) if cols else None
    d = r_on - r_off
    if not np.all(np.isfinite(d)):
        return HeldoutTest(0.0, 0.0, floor)
    pd = _project_out(b, d)
    distinct = float(pd @ pd)
    p_off, p_on = _project_out(b, r_off), _project_out(b, r_on)
    confirmed = float(p_off @ p_off - p_on @ p_on)
    return HeldoutTest(distinct, confirmed, floor)


__all__ = ["CONFIRM_SHARE", "HeldoutTest", "heldout_test"]
