"""Simulation of a model on a log's input: the shared kernel plus sensor effects.

:func:`param_vector` turns a :class:`~pmdcid.model.Model` into the kernel's flat vector (effects
not listed in the model held neutral); :func:`simulate` runs it on an input and returns what the
sensors would read.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pmdcid.errors import ModelError
from pmdcid.model import EFFECTS, Model
from pmdcid.model.params import BASE_PARAMS
from pmdcid.simulate.cache import invalidate_if_stale

invalidate_if_stale()  # before anything compiled is loaded from the cache

from pmdcid.simulate.kernel import choose_substeps, run_kernel  # noqa: E402
from pmdcid.simulate.layout import INDEX, NAMES, SENSOR_NAMES  # noqa: E402
from pmdcid.simulate.sensors import apply_sensors  # noqa: E402


@dataclass
class SimResult:
    """Simulated measurements at the log instants: t [s], i [A], omega [rad/s], theta [rad].

    ``omega`` and ``theta`` are as the sensors read them (sensor effects applied);
    ``omega_true``/``theta_true`` are the rotor's.
    """

    t: np.ndarray
    i: np.ndarray
    omega: np.ndarray
    theta: np.ndarray
    omega_true: np.ndarray
    theta_true: np.ndarray

    def get(self, name: str) -> np.ndarray:
        return getattr(self, name)


def neutral_values() -> dict[str, float]:
    """Every kernel and sensor parameter at the value that switches its effect off."""
    vals = {n: BASE_PARAMS[n].neutral for n in BASE_PARAMS}
    for eff in EFFECTS.values():
        for ps in eff.params:
            vals[ps.name] = ps.neutral
    return vals


def param_values(model: Model, torque_driven: bool = False,
                 overrides: dict[str, float] | None = None) -> dict[str, float]:
    """Effective parameter values for simulation (SI), effects not in the model neutral.

    ``bv`` falls back to the paper's linear ``b`` when the nonlinear stage has not run yet.
    For torque-driven logs R, L and km are not needed.
    """
    vals = neutral_values()
    active = {p.name for e in model.effects for p in EFFECTS[e].params}
    for name, par in model.parameters.items():
        if name in BASE_PARAMS or name in active:
            vals[name] = par.value
    if "bv" not in model.parameters and "b" in model.parameters:
        vals["bv"] = model.parameters["b"].value
    if overrides:
        vals.update(overrides)
    need = ["J"] if torque_driven else ["R", "L", "km", "J"]
    missing = [n for n in need if not np.isfinite(vals.get(n, np.nan))]
    if missing:
        raise ModelError(
            f"model lacks {', '.join(missing)} needed to simulate "
            f"({'run fit-electrical and give --km' if 'R' in missing else 'run fit-mechanical'})",
            model.path,
        )
    if torque_driven:
        for n in ("R", "L", "km"):
            if not np.isfinite(vals[n]):
                vals[n] = 1.0
    return vals


def param_vector(vals: dict[str, float]) -> np.ndarray:
    """Flat kernel vector (layout :data:`pmdcid.simulate.layout.NAMES`)."""
    return np.array([vals[n] for n in NAMES], dtype=float)


def simulate_values(t: np.ndarray, u: np.ndarray, vals: dict[str, float],
                    torque_driven: bool = False, nsub: int | None = None) -> SimResult:
    """Simulate from rest with parameter values ``vals`` (see :func:`param_values`)."""
    t = np.asarray(t, dtype=float)
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    p = param_vector(vals)
    x = run_kernel(u, dt, p, torque_driven, nsub)
    sensor = {n: vals.get(n, 0.0) for n in SENSOR_NAMES}
    om, th = apply_sensors(t, x[:, 1], x[:, 2], sensor)
    i = np.full(len(t), np.nan) if torque_driven else x[:, 0]
    return SimResult(t, i, om, th, x[:, 1], x[:, 2])


def simulate(t: np.ndarray, u: np.ndarray, model: Model, torque_driven: bool = False,
             nsub: int | None = None, overrides: dict[str, float] | None = None) -> SimResult:
    """Simulate ``model`` from rest under input ``u`` (V, or N m if ``torque_driven``) at ``t``."""
    from pmdcid.simulate.kernel import bounded_for

    vals = param_values(model, torque_driven, overrides)
    with bounded_for(model.path):
        return simulate_values(t, u, vals, torque_driven, nsub)


def simulate_log(log, model: Model, nsub: int | None = None,
                 overrides: dict[str, float] | None = None) -> SimResult:
    """Simulate ``model`` on a :class:`~pmdcid.io.Log`'s input column."""
    return simulate(log.t, log.u, model, log.drive == "tau", nsub, overrides)


__all__ = [
    "INDEX", "NAMES", "SimResult", "choose_substeps", "neutral_values", "param_values",
    "param_vector", "run_kernel", "simulate", "simulate_log", "simulate_values",
]
