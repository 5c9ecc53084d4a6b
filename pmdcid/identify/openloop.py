"""Open-loop validation figures on measured logs.

:func:`velocity_error` is the EMPS benchmark's figure (Janot, Gautier, Brunot 2019; see
``fixtures/emps/CITATION.md``): the model is simulated open loop from rest on the log's input,
the measured speed is the angle filtered by a 4th-order zero-phase Butterworth (default 100 Hz)
and differentiated (central differences), the first ``skip`` samples are left out, and

    error [%] = 100 * ||v - v_sim|| / ||v||.

With the authors' parameters it gives 4.92 % on the estimation file and 7.27 % on the validation
file (their README: 4.90 % and 7.27 %).
"""

from __future__ import annotations

import numpy as np

from pmdcid.io.derive import kinematics_from_position, kinematics_from_speed
from pmdcid.model import Model
from pmdcid.simulate import simulate_log

#: the benchmark's filter cut-off [Hz] and number of leading samples left out
EMPS_CUTOFF_HZ = 100.0
EMPS_SKIP = 49


def measured_speed(log, cutoff_hz: float = EMPS_CUTOFF_HZ) -> np.ndarray:
    """Speed [rad/s or m/s] from the log's measured angle (or its measured speed), filtered."""
    derived = getattr(log, "derived", set())
    if log.has("theta") and "theta" not in derived:
        return kinematics_from_position(log["theta"], log.dt, cutoff_hz).omega
    log.require("omega", purpose="the velocity error")
    return kinematics_from_speed(log["omega"], log.dt, cutoff_hz).omega


def velocity_error(log, model: Model, cutoff_hz: float = EMPS_CUTOFF_HZ,
                   skip: int = EMPS_SKIP) -> float:
    """Open-loop relative velocity error [%] of ``model`` on ``log`` (definition above)."""
    v = measured_speed(log, cutoff_hz)
    sim = simulate_log(log, model).omega
    return float(100.0 * np.linalg.norm(v[skip:] - sim[skip:]) / np.linalg.norm(v[skip:]))
