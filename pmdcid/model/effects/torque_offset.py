"""Constant load torque tau0 opposing positive motion (gravity, spring preload).

Equivalent to direction-asymmetric Coulomb friction bc+tau0 forward, bc-tau0 backward.
Signature: speed residual of one sign in both directions; drift at rest if |tau0| > bc.
"""

from __future__ import annotations

from pmdcid.model.effects.probes import linear, torque_probe
from pmdcid.model.effects.registry import Effect
from pmdcid.model.spec import ParamSpec

EFFECT = Effect(
    "torque_offset", __doc__,
    (ParamSpec("tau0", "N m", "constant load torque", 0.0, -1e6, 1e6),),
    "mechanical",
    ("bc",),
    **linear("tau0", torque_probe, positive=False),
    record="motion in both directions (steps of both signs, a triangle through zero)",
)
