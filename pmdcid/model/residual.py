"""What an effect's signature and starting-guess functions see: the residual of the current model.

The diagnose stage fills a :class:`ResidualContext` (plain numpy arrays, SI units) and asks each
catalogue effect for its :class:`Probe` s: small parameter settings that switch the effect on. The
simulated change each probe column makes is the effect's *signature* in the residual; diagnose
regresses the residual on it (together with the base parameters the effect interacts with) and
hands the coefficients back to the effect's ``guess`` to get a starting point for the refit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class LogResidual:
    """One log as the current model sees it (all arrays at the log's own instants).

    ``u`` is the input (V, or N m when ``torque_driven``); ``omega``/``theta`` the measured speed
    [rad/s] and angle [rad] (None when the log has none, e.g. blocked rotor); ``omega_sim`` the
    model's speed; ``resid`` maps signal name -> measured minus simulated (NaN where the sample is
    not used for fitting); ``bandwidth`` [Hz] the highest frequency the speed can show: the
    cut-off of the low-pass a speed derived from the angle went through (inf: a measured speed,
    up to the sampling's own Nyquist frequency).
    """

    t: np.ndarray
    u: np.ndarray
    torque_driven: bool
    blocked: bool
    omega: np.ndarray | None
    theta: np.ndarray | None
    omega_sim: np.ndarray
    resid: dict[str, np.ndarray] = field(default_factory=dict)
    bandwidth: float = math.inf

    @property
    def dt(self) -> float:
        return float((self.t[-1] - self.t[0]) / max(len(self.t) - 1, 1))


@dataclass
class ResidualContext:
    """The residual of the current model over every log, with the model's parameter values.

    Scales (all > 0) size the probes: ``torque_scale`` [N m] typical friction/load torque,
    ``speed_scale`` [rad/s] typical |speed|, ``voltage_scale`` [V] largest |v| (0 if no voltage
    input), ``dt`` [s] the shortest sample period.
    """

    values: dict[str, float]
    logs: list[LogResidual]
    torque_scale: float
    speed_scale: float
    voltage_scale: float
    dt: float

    def moving(self):
        """(log, mask of samples where the rotor turns) for logs that measure speed."""
        for lg in self.logs:
            if lg.omega is None or lg.theta is None:
                continue
            yield lg, np.abs(lg.omega_sim) > 0.02 * self.speed_scale


@dataclass
class Probe:
    """One way of switching an effect on: columns of parameter overrides, each small.

    Diagnose simulates the model with each column's overrides; the change in the simulated
    signals is one regressor. ``label`` says which alternative this is (e.g. ``ws=0.3``).
    """

    columns: list[dict[str, float]]
    label: str = ""


__all__ = ["LogResidual", "Probe", "ResidualContext"]
