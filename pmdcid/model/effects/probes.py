"""What the effects' probes share (pure functions of the residual context).

An effect's ``signature(ctx) -> list[Probe]`` proposes one or a few small settings of its
parameters (alternatives for parameters that enter non-linearly: a Stribeck speed, a cogging
order, a voltage limit); its ``guess(probe, coefs, ctx) -> dict | None`` turns the regression
coefficients of the residual on the probe's columns into starting values, or None when the sign
is impossible (e.g. negative static friction: the residual does not point at this effect).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pmdcid.model.residual import Probe, ResidualContext

#: probe sizes, as fractions of the context scales (small: linear regime; not tiny: stick-slip
#: events quantise the simulated response)
PROBE = 0.05


def linear(param: str, size: Callable[[ResidualContext], float], positive: bool = True):
    """``{signature, guess}`` for an effect with one amplitude parameter entering near-linearly."""

    def signature(ctx: ResidualContext) -> list[Probe]:
        return [Probe([{param: size(ctx)}])]

    def guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
        v = float(coefs[0]) * probe.columns[0][param]
        if not math.isfinite(v) or (positive and v <= 0.0):
            return None
        return {param: v}

    return {"signature": signature, "guess": guess}


def torque_probe(ctx: ResidualContext) -> float:
    """[N m] a few percent of the typical friction torque."""
    return PROBE * ctx.torque_scale


def delay_probe(ctx: ResidualContext) -> float:
    """[s] one sample period."""
    return ctx.dt


__all__ = ["PROBE", "delay_probe", "linear", "torque_probe"]
