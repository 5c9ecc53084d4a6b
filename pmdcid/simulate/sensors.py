"""Sensor effects, applied to the kernel's true states to give what the sensors read."""

from __future__ import annotations

import numpy as np


def delayed(t: np.ndarray, x: np.ndarray, delay: float) -> np.ndarray:
    """``x`` read ``delay`` seconds late (linear interpolation; the initial value before t0)."""
    if delay <= 0.0:
        return x
    return np.interp(t - delay, t, x, left=x[0])


def apply_sensors(t: np.ndarray, omega: np.ndarray, theta: np.ndarray, sensor: dict[str, float]):
    """Measured speed [rad/s] and angle [rad] from true ones: sensor_delay, speed_offset."""
    d = float(sensor.get("delay", 0.0))
    om = delayed(t, omega, d) + float(sensor.get("omega0", 0.0))
    th = delayed(t, theta, d)
    return om, th
