"""Friction growing with speed squared: friction gains bq*omega*|omega| (windage, lubricant).

bq < 0 is friction flattening with speed, bounded so that the total friction stays positive over
the logged speeds. Signature: speed residual proportional to -omega*|omega|; high speeds
over-predicted (bq > 0) or under-predicted (bq < 0).
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects.friction import (
    FRICTION_ROOM,
    MIN_MOVING,
    TOP_QUANTILE,
    moving_speeds,
    paper_friction,
)
from pmdcid.model.effects.probes import PROBE, linear
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.model.spec import ParamSpec


def probe_size(ctx: ResidualContext) -> float:
    """[N m s^2/rad^2] drag giving a few percent of the friction torque at the typical speed."""
    return PROBE * ctx.torque_scale / ctx.speed_scale**2


def limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """bq [N m s^2/rad^2] at least -0.9 (bc + bv w)/w^2 at the top logged speed w: a negative
    drag (friction flattening with speed) keeps the total friction positive over the logged
    speeds (bc + bv|omega| + bq omega^2 is concave in |omega| for bq < 0, so its minimum over
    [0, w] is at an end)."""
    w = moving_speeds(ctx)
    if len(w) < MIN_MOVING:
        return {"bq": (0.0, math.inf)}
    top = float(np.quantile(w, TOP_QUANTILE))
    return {"bq": (-FRICTION_ROOM * paper_friction(ctx, top) / top**2, math.inf)}


EFFECT = Effect(
    "quadratic_drag", __doc__,
    (ParamSpec("bq", "N m s^2/rad^2", "quadratic drag coefficient (negative: friction "
               "flattening with speed)", 0.0, -1e6, 1e6),),
    "mechanical",
    ("bv",),
    **linear("bq", probe_size, positive=False),
    limits=limits,
    record=("steady speeds spanning the range, in logs of their own (a staircase of levels or "
            "steps to several voltages)"),
)
