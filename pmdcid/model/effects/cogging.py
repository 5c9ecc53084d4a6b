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
    """Power of the speed residual's harmonics in rotor angle over its noise floor, index n =
    periods per revolution (n = 0 .. ANGLE_BINS/2).

    The residual of every moving sample is binned by measured angle modulo 2 pi; the mean per
    bin (empty bins 0) is Fourier-transformed. An order is read only from the samples that
    resolve it: between two samples the rotor turns |omega| dt, and n periods per revolution
    are sampled above their Nyquist rate only where n |omega| dt < pi (faster, a speed measured
    over a sample averages the ripple out and the samples alias it; so does the kernel's step),
    and a speed derived from the angle through a low-pass at f_c shows them only where
    n |omega| < 2 pi f_c (bench/newrigs.py lego seed 7, 11 ms loop-timed samples and a 9 Hz
    derivation filter: order 71 read from the starts from rest, where every log turns its first
    few degrees from the angle 0 through the gear's play, was added and raised the held-out
    sines 17-30 %).
    Each octave of orders is read from the samples resolving its top order, its |c_n|^2 over
    the power white noise would give there (sum over bins of variance / count), so that
    octaves read from fewer samples are not favoured.
    """
    bins, resid, reach = [], [], []
    for lg, mov in ctx.moving():
        r = lg.resid.get("omega")
        if r is None:
            continue
        ok = mov & np.isfinite(r)
        if ok.sum() < 10:
            continue
        bins.append((np.mod(lg.theta[ok], 2 * math.pi) / (2 * math.pi) * ANGLE_BINS)
                    .astype(int).clip(0, ANGLE_BINS - 1))
        resid.append(r[ok] - np.mean(r[ok]))
        w = np.maximum(np.abs(lg.omega_sim[ok]), 1e-300)
        reach.append(np.minimum(math.pi / (w * lg.dt), 2 * math.pi * lg.bandwidth / w))
    out = np.zeros(ANGLE_BINS // 2 + 1)
    if not bins:
        return out
    k, rr, top = np.concatenate(bins), np.concatenate(resid), np.concatenate(reach)
    lo = 1
    while lo <= ANGLE_BINS // 2:
        hi = min(2 * lo, ANGLE_BINS // 2 + 1)
        sel = top > hi - 1
        out[lo:hi] = _whitened_power(k[sel], rr[sel])[lo:hi]
        lo = hi
    return out


def _whitened_power(k: np.ndarray, rr: np.ndarray) -> np.ndarray:
    """|c_n|^2 of the per-bin mean residual over white noise's expectation (0 with too few
    samples)."""
    if k.size < 10:
        return np.zeros(ANGLE_BINS // 2 + 1)
    counts = np.bincount(k, None, ANGLE_BINS)
    mean = np.where(counts > 0, np.bincount(k, rr, ANGLE_BINS) / np.maximum(counts, 1), 0.0)
    floor = float(np.var(rr)) * float(np.sum(1.0 / counts[counts > 0]))
    return np.abs(np.fft.rfft(mean)) ** 2 / max(floor, 1e-300)


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
