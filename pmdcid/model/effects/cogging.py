"""Cogging torque periodic in rotor angle: -ca*sin(cn*theta + cphi).

cn periods per revolution (an integer, slots x poles), read from the residual's spectrum in rotor
angle and held. Signature: residual periodic in theta, line at cn in the angle spectrum; speed
ripple at cn*omega/(2 pi) Hz.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects.probes import torque_probe
from pmdcid.model.effects.registry import Effect
from pmdcid.model.residual import Probe, ResidualContext
from pmdcid.model.spec import ParamSpec

ANGLE_BINS = 1024
#: cogging orders tried (the strongest lines of the angle spectrum)
COGGING_ORDERS = 3


def angle_spectrum(ctx: ResidualContext) -> np.ndarray:
    """Power of the speed residual's harmonics in rotor angle, index n = periods per revolution.

    The residual of every moving sample is binned by measured angle modulo 2 pi; the mean per bin
    (empty bins 0) is Fourier-transformed. Returns |c_n|^2 for n = 0 .. ANGLE_BINS/2.
    """
    sums = np.zeros(ANGLE_BINS)
    counts = np.zeros(ANGLE_BINS)
    for lg, mov in ctx.moving():
        r = lg.resid.get("omega")
        if r is None:
            continue
        ok = mov & np.isfinite(r)
        if ok.sum() < 10:
            continue
        rr = r[ok] - np.mean(r[ok])
        k = (np.mod(lg.theta[ok], 2 * math.pi) / (2 * math.pi) * ANGLE_BINS).astype(int)
        k = np.clip(k, 0, ANGLE_BINS - 1)
        sums += np.bincount(k, rr, ANGLE_BINS)
        counts += np.bincount(k, None, ANGLE_BINS)
    mean = np.where(counts > 0, sums / np.maximum(counts, 1), 0.0)
    return np.abs(np.fft.rfft(mean)) ** 2


def signature(ctx: ResidualContext) -> list[Probe]:
    p = angle_spectrum(ctx)
    if len(p) < 3 or not np.any(p[1:] > 0):
        return []
    orders = np.argsort(p[1:])[::-1][:COGGING_ORDERS] + 1
    ca = torque_probe(ctx)
    return [Probe([{"ca": ca, "cn": float(n), "cphi": 0.0},
                   {"ca": ca, "cn": float(n), "cphi": math.pi / 2}], f"cn={int(n)}")
            for n in orders]


def guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """-ca sin(n theta + phi) = -a sin(n theta) - b cos(n theta): a, b from the two columns."""
    col = probe.columns[0]
    a, b = float(coefs[0]) * col["ca"], float(coefs[1]) * col["ca"]
    ca = math.hypot(a, b)
    if not math.isfinite(ca) or ca <= 0:
        return None
    return {"ca": ca, "cn": col["cn"], "cphi": math.atan2(b, a)}


EFFECT = Effect(
    "cogging", __doc__,
    (ParamSpec("ca", "N m", "cogging torque amplitude", 0.0, 0.0, 1e6),
     ParamSpec("cn", "1/rev", "cogging periods per revolution", 0.0, 0.0, 1000.0),
     ParamSpec("cphi", "rad", "cogging phase", 0.0, -2 * math.pi, 2 * math.pi)),
    "mechanical",
    (),
    signature=signature,
    guess=guess,
    held=("cn",),
    record="slow, steady runs over several revolutions",
)
