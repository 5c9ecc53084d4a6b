"""Physics terms evaluated inside the compiled kernel: small pure functions, SI units.

All take the flat kernel parameter vector ``p`` (layout :data:`pmdcid.simulate.layout.NAMES`).
Effects that are switched off hold neutral values, which make their terms vanish exactly.
"""

from __future__ import annotations

import math

from pmdcid.simulate.layout import (
    BC,
    BQ,
    BV,
    CA,
    CN,
    CPHI,
    CURVE_KNOTS,
    DBV,
    DZ,
    DZ_OFFSET,
    DZ_SLOPE,
    FC1,
    FCW1,
    FS,
    KE,
    SIGMA0,
    SIGMA1,
    TAU0,
    VB,
    VMAX,
    WS,
    R,
)
from pmdcid.simulate.lazyjit import njit


@njit(cache=True, inline="always")
def sgn(x: float) -> float:
    """sign(x) with sign(0) = 0."""
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@njit(cache=True, inline="always")
def drive_voltage(p, v: float) -> float:
    """Voltage the drive actually applies [V]: clipped to +-vmax (voltage_saturation)."""
    vmax = p[VMAX]
    if v > vmax:
        return vmax
    if v < -vmax:
        return -vmax
    return v


@njit(cache=True, inline="always")
def armature_voltage(p, v: float, omega: float) -> float:
    """Voltage across R and L plus back-EMF after the brush drop [V] (brush_drop).

    The brushes take up to ``vb`` of the driving voltage v - ke*omega, opposing it; the part of
    the back-EMF itself is handled by the kernel's exact linear step.
    """
    vb = p[VB]
    if vb <= 0.0:
        return v
    drive = v - p[KE] * omega
    drop = min(max(drive, -vb), vb)
    return v - drop


@njit(cache=True, inline="always")
def instant_current(p, v: float, omega: float) -> float:
    """Armature current [A] of a winding without inductance (L = 0) at drive voltage v [V]
    and speed omega [rad/s]: (v - ke omega) / R, after the brush drop
    (:func:`armature_voltage`). A lumped model whose electrical lag is below what its logs
    resolve (tau_e = 0 with the back-EMF's share known, :mod:`pmdcid.model.lumped`) runs so:
    the dead zone then acts on v - ke omega, where the physics puts it."""
    return (armature_voltage(p, v, omega) - p[KE] * omega) / p[R]


@njit(cache=True, inline="always")
def dead_zone_engaged(p, torque: float) -> bool:
    """True when the magnetic torque [N m] is at or beyond the hard dead zone's break point."""
    return abs(torque) >= p[DZ]


@njit(cache=True, inline="always")
def dead_zone(p, torque: float) -> float:
    """Hard dead zone (paper eq. 7) at torque level [N m]: 0 inside, sign*(k|T| + k_hat) outside."""
    if abs(torque) < p[DZ]:
        return 0.0
    return p[DZ_SLOPE] * torque + p[DZ_OFFSET] * sgn(torque)


@njit(cache=True, inline="always")
def static_friction(p) -> float:
    """Breakaway torque [N m]: Coulomb plus Stribeck static excess."""
    return p[BC] + p[FS]


@njit(cache=True, inline="always")
def friction_curve(p, speed: float) -> float:
    """Friction added at ``speed`` = |omega| [rad/s] by the friction_curve effect [N m].

    Piecewise linear through (0, 0), the knots (fcw_k [rad/s], fc_k [N m]) for k = 1..3 and
    (fcw4, 0), knot speeds increasing; 0 beyond fcw4 (past the logged speeds the paper's
    bc + bv*|omega| continues). Pinned to 0 at both ends so that it is neither Coulomb friction
    (the jump at 0) nor viscous friction (the line through the last knot). Zero when fcw4 is
    not positive (the effect is off).
    """
    if p[FCW1 + CURVE_KNOTS - 1] <= 0.0:
        return 0.0
    w0 = 0.0
    f0 = 0.0
    for k in range(CURVE_KNOTS):
        w1 = p[FCW1 + k]
        f1 = p[FC1 + k] if k < CURVE_KNOTS - 1 else 0.0
        if speed <= w1:
            if w1 <= w0:
                return f1
            return f0 + (f1 - f0) * (speed - w0) / (w1 - w0)
        w0 = w1
        f0 = f1
    return 0.0


@njit(cache=True, inline="always")
def friction_guarded(p) -> bool:
    """True when :func:`sliding_friction` needs its friction curve and its positivity hold.

    False when the curve is off (fcw4 <= 0) and every friction term is non-negative in the
    sliding direction (bc, fs, bq, bv >= 0, dbv = 0): then the curve adds nothing and the hold
    can never act, so skipping both gives the same value. The kernel evaluates this once per
    simulation: the two terms sit on the step's critical path (speed -> friction -> speed) and
    cost about 8 ns of a 20 ns step when evaluated every step (issue #16).
    """
    return not (p[FCW1 + CURVE_KNOTS - 1] <= 0.0 and p[BC] >= 0.0 and p[FS] >= 0.0
                and p[BQ] >= 0.0 and p[BV] >= 0.0 and p[DBV] == 0.0)


#: exp(-x) is exactly 0.0 in double precision for x above this (the smallest subnormal is
#: exp(-744.44); exp(-745.14) and beyond round to 0). glibc's exp takes a slow underflow path
#: there (14 ns against 9): skipping the call gives the same bits
EXP_ZERO = 746.0


@njit(cache=True, inline="always")
def stribeck_excess(p, omega: float) -> float:
    """Stribeck's static excess fs*exp(-(omega/ws)^2) [N m] at speed ``omega`` [rad/s]; 0 when
    fs is not positive (the effect is off). Beyond sqrt(746) ws (about 27 ws, where the
    exponential is exactly 0 in double precision) the exponential is not evaluated."""
    if p[FS] <= 0.0:
        return 0.0
    r = omega / p[WS]
    r2 = r * r
    if r2 > EXP_ZERO:  # (a NaN still goes through exp and stays NaN)
        return 0.0
    return p[FS] * math.exp(-r2)


@njit(cache=True, inline="always")
def sliding_friction(p, omega: float, direction: float, guarded: bool = True) -> float:
    """Friction torque [N m] while sliding in ``direction`` (+1/-1), less the viscous bv*omega.

    Coulomb bc, Stribeck fs*exp(-(omega/ws)^2), quadratic drag bq*omega*|omega|, the
    direction-dependent part of the viscous friction dbv*|omega| (viscous bv + dbv forward,
    bv - dbv backward) and the friction curve direction*curve(|omega|).

    The total with the viscous part never opposes ``direction``: where the terms would sum to a
    friction that drives the rotor (a negative quadratic drag past the logged speeds), the total
    is held at zero (frictionless) instead. ``guarded`` False (:func:`friction_guarded` of the
    same ``p``) skips the curve and the hold, which then cannot change the value.
    """
    f = direction * p[BC] + direction * stribeck_excess(p, omega)
    f += p[BQ] * omega * abs(omega)
    f += p[DBV] * abs(omega)
    if guarded:
        f += direction * friction_curve(p, abs(omega))
        if direction * (f + p[BV] * omega) < 0.0:
            f = -p[BV] * omega
    return f


@njit(cache=True, inline="always")
def lugre_on(p) -> bool:
    """True when LuGre dynamic friction replaces the stick-slip logic (sigma0 > 0)."""
    return p[SIGMA0] > 0.0


@njit(cache=True, inline="always")
def lugre_damping(p) -> float:
    """LuGre's micro-damping sigma1 [N m s/rad] while LuGre is on, 0 off: the part of
    sigma1 dz/dt proportional to omega, integrated with bv by the exact linear step."""
    if lugre_on(p):
        return p[SIGMA1]
    return 0.0


@njit(cache=True, inline="always")
def steady_friction_level(p, omega: float) -> float:
    """LuGre's g(omega) [N m]: the Coulomb + Stribeck level bc + fs*exp(-(omega/ws)^2) the
    bristles settle at when sliding steadily at omega [rad/s]."""
    return p[BC] + stribeck_excess(p, omega)


@njit(cache=True, inline="always")
def bristle_rate(p, omega: float) -> float:
    """Relaxation rate a = sigma0*|omega|/g(omega) [1/s] of the bristle deflection z:
    dz/dt = omega - a z (infinite when g = 0: no Coulomb level, the bristles hold nothing)."""
    g = steady_friction_level(p, omega)
    if g <= 0.0:
        return math.inf
    return p[SIGMA0] * abs(omega) / g


@njit(cache=True, inline="always")
def lugre_held_friction(p, omega: float, z: float, a: float) -> float:
    """LuGre friction [N m] less its exact viscous part (bv + sigma1)*omega, held over a step:
    sigma0*z - sigma1*a*z (the bristles' spring and the rest of sigma1*dz/dt), plus the speed
    terms of the other effects (quadratic drag, direction-dependent viscous)."""
    az = a * z if z != 0.0 else 0.0
    return (p[SIGMA0] * z - p[SIGMA1] * az + p[BQ] * omega * abs(omega)
            + p[DBV] * abs(omega))


@njit(cache=True, inline="always")
def bristle_step(z: float, a: float, h: float, dtheta: float) -> float:
    """Bristle deflection [rad] after a step of h [s] that turned the rotor by dtheta [rad]:
    dz/dt = w - a z solved exactly with rate a [1/s] held and w the step's mean speed
    dtheta/h. Stable for any stiffness; a = 0 (at rest) gives z + dtheta (pure presliding)."""
    ah = a * h
    if ah > 700.0:
        return dtheta / ah if math.isfinite(ah) else 0.0
    if ah < 1e-9:
        return (1.0 - ah) * z + dtheta * (1.0 - 0.5 * ah)
    return math.exp(-ah) * z - math.expm1(-ah) / ah * dtheta


@njit(cache=True, inline="always")
def load_torque(p, theta: float) -> float:
    """Torque [N m] opposing motion that does not depend on speed: tau0 + cogging(theta)."""
    t = p[TAU0]
    if p[CA] != 0.0:
        t += p[CA] * math.sin(p[CN] * theta + p[CPHI])
    return t


__all__ = [
    "armature_voltage", "bristle_rate", "bristle_step", "dead_zone", "dead_zone_engaged",
    "drive_voltage", "friction_curve", "friction_guarded", "instant_current", "load_torque",
    "lugre_damping", "lugre_held_friction", "lugre_on", "sgn", "sliding_friction",
    "static_friction", "steady_friction_level", "stribeck_excess", "BV",
]
