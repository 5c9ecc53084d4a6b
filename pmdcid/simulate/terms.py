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
    DBV,
    DZ,
    DZ_OFFSET,
    DZ_SLOPE,
    FS,
    KE,
    TAU0,
    VB,
    VMAX,
    WS,
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
def sliding_friction(p, omega: float, direction: float) -> float:
    """Friction torque [N m] while sliding in ``direction`` (+1/-1), less the viscous bv*omega.

    Coulomb bc, Stribeck fs*exp(-(omega/ws)^2), quadratic drag bq*omega*|omega| and the
    direction-dependent part of the viscous friction dbv*|omega| (viscous bv + dbv forward,
    bv - dbv backward).
    """
    f = direction * p[BC]
    if p[FS] > 0.0:
        r = omega / p[WS]
        f += direction * p[FS] * math.exp(-r * r)
    f += p[BQ] * omega * abs(omega)
    f += p[DBV] * abs(omega)
    return f


@njit(cache=True, inline="always")
def load_torque(p, theta: float) -> float:
    """Torque [N m] opposing motion that does not depend on speed: tau0 + cogging(theta)."""
    t = p[TAU0]
    if p[CA] != 0.0:
        t += p[CA] * math.sin(p[CN] * theta + p[CPHI])
    return t


__all__ = [
    "armature_voltage", "dead_zone", "dead_zone_engaged", "drive_voltage", "load_torque", "sgn",
    "sliding_friction", "static_friction", "BV",
]
