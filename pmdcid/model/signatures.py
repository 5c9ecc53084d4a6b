"""Signature probes and starting guesses of the catalogue effects (pure functions of numpy arrays).

For each effect, ``signature(ctx) -> list[Probe]`` proposes one or a few small settings of its
parameters (alternatives for parameters that enter non-linearly: a Stribeck speed, a cogging
order, a voltage limit); ``guess(probe, coefs, ctx) -> dict | None`` turns the regression
coefficients of the residual on the probe's columns into starting values, or None when the sign
is impossible (e.g. negative static friction: the residual does not point at this effect).
The registry in :mod:`pmdcid.model.effects` attaches them to the effects.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from pmdcid.model.context import Probe, ResidualContext

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


def speed_probe(ctx: ResidualContext) -> float:
    """[rad/s] a few percent of the typical speed."""
    return PROBE * ctx.speed_scale


def voltage_probe(ctx: ResidualContext) -> float:
    """[V] a few percent of the largest voltage."""
    return PROBE * max(ctx.voltage_scale, 1e-6)


def delay_probe(ctx: ResidualContext) -> float:
    """[s] one sample period."""
    return ctx.dt


def quadratic_probe(ctx: ResidualContext) -> float:
    """[N m s^2/rad^2] drag giving a few percent of the friction torque at the typical speed."""
    return PROBE * ctx.torque_scale / ctx.speed_scale**2


def viscous_probe(ctx: ResidualContext) -> float:
    """[N m s/rad] a viscous difference giving a few percent of the friction torque at the
    typical speed."""
    return PROBE * ctx.torque_scale / ctx.speed_scale


def viscous_asymmetry_limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """|dbv| below 0.9 bv: the viscous friction stays positive in both directions."""
    bv = ctx.values.get("bv", math.nan)
    if not (math.isfinite(bv) and bv > 0):
        return {}
    return {"dbv": (-0.9 * bv, 0.9 * bv)}


def back_emf_probe(ctx: ResidualContext) -> float:
    """[V s/rad] a few percent of km (ke = km in SI units)."""
    km = ctx.values.get("km", math.nan)
    if not math.isfinite(km) or km <= 0:
        km = 1.0
    return PROBE * km


# --- stribeck: the Stribeck speed enters non-linearly: a few alternatives -----------------------

#: Stribeck speeds tried, as fractions of the typical speed
STRIBECK_SPEEDS = (0.02, 0.06, 0.2)


def stribeck_signature(ctx: ResidualContext) -> list[Probe]:
    fs = torque_probe(ctx)
    return [Probe([{"fs": fs, "ws": f * ctx.speed_scale}], f"ws={f * ctx.speed_scale:.3g}")
            for f in STRIBECK_SPEEDS]


def stribeck_guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    col = probe.columns[0]
    fs = float(coefs[0]) * col["fs"]
    if not math.isfinite(fs) or fs <= 0:
        return None
    return {"fs": fs, "ws": col["ws"]}


def stribeck_limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """ws [rad/s] below half the typical speed: a Stribeck curve that decays only at the top
    speeds is Coulomb friction with a speed-squared correction (quadratic drag's signature)."""
    return {"ws": (1e-3 * ctx.speed_scale, 0.5 * ctx.speed_scale)}


# --- cogging: the order from the residual's spectrum in rotor angle -----------------------------

ANGLE_BINS = 1024


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


#: cogging orders tried (the strongest lines of the angle spectrum)
COGGING_ORDERS = 3


def cogging_signature(ctx: ResidualContext) -> list[Probe]:
    p = angle_spectrum(ctx)
    if len(p) < 3 or not np.any(p[1:] > 0):
        return []
    orders = np.argsort(p[1:])[::-1][:COGGING_ORDERS] + 1
    ca = torque_probe(ctx)
    return [Probe([{"ca": ca, "cn": float(n), "cphi": 0.0},
                   {"ca": ca, "cn": float(n), "cphi": math.pi / 2}], f"cn={int(n)}")
            for n in orders]


def cogging_guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """-ca sin(n theta + phi) = -a sin(n theta) - b cos(n theta): a, b from the two columns."""
    col = probe.columns[0]
    a, b = float(coefs[0]) * col["ca"], float(coefs[1]) * col["ca"]
    ca = math.hypot(a, b)
    if not math.isfinite(ca) or ca <= 0:
        return None
    return {"ca": ca, "cn": col["cn"], "cphi": math.atan2(b, a)}


# --- voltage_saturation: the limit enters non-linearly: a few alternatives ----------------------

SATURATION_FRACTIONS = (0.95, 0.85, 0.7, 0.5)


def saturation_signature(ctx: ResidualContext) -> list[Probe]:
    if ctx.voltage_scale <= 0:
        return []
    return [Probe([{"vmax": f * ctx.voltage_scale}], f"vmax={f * ctx.voltage_scale:.3g}")
            for f in SATURATION_FRACTIONS]


def saturation_guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """The probe is the full effect at that limit: keep it when the residual follows it."""
    if not (float(coefs[0]) > 0.3):
        return None
    return {"vmax": probe.columns[0]["vmax"]}


# --- friction_curve: knots placed by the logged speeds; quadratic drag's room below zero -------

#: inner knot speeds of friction_curve, as fractions of the top logged speed (the last knot);
#: denser at low speed, where friction changes fastest. Not quantiles of |omega|: those crowd
#: the knots where the logs dwell (step plateaus, slow ramps) and leave the top of the speed
#: range to one long segment
CURVE_FRACTIONS = (0.15, 0.4, 0.7)
#: the top of the logged speeds: this quantile of the measured |omega| while moving (a few
#: noise spikes above it do not count as logged speeds)
TOP_QUANTILE = 0.999
#: a friction effect may take at most this share of the paper's friction bc + bv*|omega| away
#: at any logged speed (refit bounds): the total sliding friction stays positive
FRICTION_ROOM = 0.9
#: at least this many moving samples are needed to place the knots
MIN_MOVING = 50


def moving_speeds(ctx: ResidualContext) -> np.ndarray:
    """Measured |omega| [rad/s] of every sample where the rotor turns (above 2 % of the typical
    speed), over all logs with a speed; measured, so the same for every model state."""
    out = [np.abs(lg.omega[np.isfinite(lg.omega)]) for lg in ctx.logs if lg.omega is not None]
    w = np.concatenate(out) if out else np.zeros(0)
    return w[w > 0.02 * ctx.speed_scale]


def curve_knots(ctx: ResidualContext) -> list[float]:
    """friction_curve's knot speeds [rad/s], increasing: the top logged speed (the
    :data:`TOP_QUANTILE` of the moving speeds) times :data:`CURVE_FRACTIONS`, and the top
    itself; [] when too few samples move."""
    w = moving_speeds(ctx)
    if len(w) < MIN_MOVING:
        return []
    top = float(np.quantile(w, TOP_QUANTILE))
    return [f * top for f in CURVE_FRACTIONS] + [top] if top > 0 else []


def paper_friction(ctx: ResidualContext, speed: float) -> float:
    """bc + bv*speed [N m] of the context's model (0 where it has none)."""
    bc, bv = (ctx.values.get(n, 0.0) for n in ("bc", "bv"))
    bc = bc if math.isfinite(bc) and bc > 0 else 0.0
    bv = bv if math.isfinite(bv) and bv > 0 else 0.0
    return bc + bv * speed


def _knot_params(knots: list[float]) -> dict[str, float]:
    return {f"fcw{k + 1}": w for k, w in enumerate(knots)}


def friction_curve_signature(ctx: ResidualContext) -> list[Probe]:
    """One probe: a small bump of friction at each inner knot in turn (one column per knot)."""
    knots = curve_knots(ctx)
    if not knots:
        return []
    size = torque_probe(ctx)
    speeds = _knot_params(knots)
    cols = [{**speeds, f"fc{k + 1}": size} for k in range(len(knots) - 1)]
    return [Probe(cols, "knots " + ", ".join(f"{w:.3g}" for w in knots) + " rad/s")]


def friction_curve_limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """fc_k [N m] at least -0.9 (bc + bv fcw_k): the curve never takes away more than 90 % of
    the paper's friction at a knot, so with bc, bv >= 0 the total stays positive over the
    logged speeds (piecewise linear between knots, 0 at 0 and from the last knot on)."""
    out = {}
    for k, w in enumerate(curve_knots(ctx)[:-1]):
        floor = paper_friction(ctx, w)
        if floor > 0:
            out[f"fc{k + 1}"] = (-FRICTION_ROOM * floor, math.inf)
    return out


def friction_curve_guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """Knot values from the regression on the bumps, raised to the limits' floor."""
    cols = probe.columns
    out = {n: v for n, v in cols[0].items() if n.startswith("fcw")}
    lim = friction_curve_limits(ctx)
    for k, col in enumerate(cols):
        name = f"fc{k + 1}"
        v = float(coefs[k]) * col[name]
        if not math.isfinite(v):
            return None
        out[name] = max(v, 0.5 * lim[name][0]) if name in lim else v
    if not any(out[f"fc{k + 1}"] != 0.0 for k in range(len(cols))):
        return None
    return out


def quadratic_drag_limits(ctx: ResidualContext) -> dict[str, tuple[float, float]]:
    """bq [N m s^2/rad^2] at least -0.9 (bc + bv w)/w^2 at the top logged speed w: a negative
    drag (friction flattening with speed) keeps the total friction positive over the logged
    speeds (bc + bv|omega| + bq omega^2 is concave in |omega| for bq < 0, so its minimum over
    [0, w] is at an end)."""
    w = moving_speeds(ctx)
    if len(w) < MIN_MOVING:
        return {"bq": (0.0, math.inf)}
    top = float(np.quantile(w, TOP_QUANTILE))
    return {"bq": (-FRICTION_ROOM * paper_friction(ctx, top) / top**2, math.inf)}


def lowest_friction(values: dict[str, float], top: float, n: int = 256) -> tuple[float, float]:
    """(smallest total sliding friction magnitude [N m], the signed speed [rad/s] where it is)
    over |omega| in (0, top], both directions, of the kernel's friction terms before its clamp:
    bc, bv, Stribeck, quadratic drag, dbv and the friction curve."""
    v = values.get
    speed = np.linspace(top / n, top, n)
    knots = [v(f"fcw{k + 1}", 0.0) for k in range(4)]
    fcs = [v(f"fc{k + 1}", 0.0) for k in range(3)]
    curve = (np.interp(speed, [0.0, *knots], [0.0, *fcs, 0.0], right=0.0)
             if knots[-1] > 0 else np.zeros_like(speed))
    fs, ws = v("fs", 0.0), v("ws", 1.0)
    strib = fs * np.exp(-(speed / ws) ** 2) if fs > 0 else 0.0
    best = (math.inf, 0.0)
    for d in (1.0, -1.0):
        mag = (v("bc", 0.0) + strib + v("bv", 0.0) * speed + v("bq", 0.0) * speed**2
               + d * v("dbv", 0.0) * speed + curve)
        j = int(np.argmin(mag))
        if mag[j] < best[0]:
            best = (float(mag[j]), d * float(speed[j]))
    return best


# --- lugre: the bristle stiffness enters non-linearly: a few presliding displacements ---------

#: presliding displacements tried [rad]: the breakaway torque moves the rotor this far
PRESLIDING = (1e-4, 1e-3, 1e-2)


def lugre_damping(sigma0: float, J: float) -> float:
    """[N m s/rad] micro-damping making the presliding spring critically damped: 2 sqrt(sigma0 J)
    (J [kg m^2] unknown or not positive: none)."""
    if not (math.isfinite(J) and J > 0):
        return 0.0
    return 2.0 * math.sqrt(sigma0 * J)


def lugre_signature(ctx: ResidualContext) -> list[Probe]:
    """The full effect at a few bristle stiffnesses sigma0 = breakaway / displacement."""
    breakaway = ctx.values.get("bc", 0.0) + ctx.values.get("fs", 0.0)
    if not (math.isfinite(breakaway) and breakaway > 0):
        breakaway = ctx.torque_scale
    J = ctx.values.get("J", math.nan)
    out = []
    for x in PRESLIDING:
        s0 = breakaway / x
        out.append(Probe([{"sigma0": s0, "sigma1": lugre_damping(s0, J)}], f"x={x:g} rad"))
    return out


def lugre_guess(probe: Probe, coefs: np.ndarray, ctx: ResidualContext) -> dict | None:
    """The probe is the full effect at that stiffness: keep it when the residual follows it."""
    if not (float(coefs[0]) > 0.3):
        return None
    col = probe.columns[0]
    return {"sigma0": col["sigma0"], "sigma1": col["sigma1"]}


__all__ = [
    "lugre_damping", "lugre_guess", "lugre_signature",
    "angle_spectrum", "curve_knots", "friction_curve_guess", "friction_curve_limits",
    "friction_curve_signature", "lowest_friction", "moving_speeds", "quadratic_drag_limits",
    "cogging_guess", "cogging_signature", "linear", "saturation_guess",
    "saturation_signature", "stribeck_guess", "stribeck_limits", "stribeck_signature",
    "viscous_asymmetry_limits", "viscous_probe",
]
