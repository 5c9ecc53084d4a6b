"""Simulation of a model on a log's input: the shared kernel plus sensor effects.

:func:`param_vector` turns a :class:`~pmdcid.model.Model` into the kernel's flat vector (effects
not listed in the model held neutral); :func:`simulate` runs it on an input and returns what the
sensors would read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import ModelError
from pmdcid.model import EFFECTS, Model
from pmdcid.model.lumped import (
    ELECTRICAL,
    LUMPED_ONLY,
    is_lumped,
    kernel_values,
    lag_substeps,
)
from pmdcid.model.spec import BASE_PARAMS
from pmdcid.simulate.cache import invalidate_if_stale

invalidate_if_stale()  # before anything compiled is loaded from the cache


def check_layout() -> None:
    """Every parameter the registry declares (base and effects) has a slot: in the kernel's
    vector (:data:`layout.NAMES`) or among the sensor parameters. A parameter missing from both
    would be silently ignored by every simulation: an import-time error instead. Likewise the
    states effects declare (``Effect.states``) are the kernel's :data:`layout.STATE_OWNERS`."""
    from pmdcid.simulate import layout

    slots = set(layout.NAMES) | set(layout.SENSOR_NAMES)
    # b: the paper's lumped viscous, simulated as bv; a lumped model's tau_e and ke_share are
    # mapped onto R, L, km, ke, bv (pmdcid.model.lumped.kernel_values)
    declared = set(BASE_PARAMS) - {"b", *LUMPED_ONLY}
    declared |= {p.name for e in EFFECTS.values() for p in e.params}
    missing = sorted(declared - slots)
    if missing:
        raise ImportError(f"parameters without a kernel slot: {', '.join(missing)} "
                          "(add them to pmdcid/simulate/layout.py)")
    owned = {(s, e.name) for e in EFFECTS.values() for s in e.states}
    if owned != set(layout.STATE_OWNERS.items()) or not set(layout.STATE_OWNERS) <= set(
            layout.STATES):
        raise ImportError(f"effect states {sorted(owned)} do not match the kernel's "
                          f"STATE_OWNERS {sorted(layout.STATE_OWNERS.items())} "
                          "(pmdcid/simulate/layout.py)")


check_layout()

from pmdcid.simulate.initial import settled_start  # noqa: E402
from pmdcid.simulate.input_grid import read_input  # noqa: E402
from pmdcid.simulate.kernel import run_kernel  # noqa: E402
from pmdcid.simulate.layout import (  # noqa: E402
    I_STATE,
    INDEX,
    NAMES,
    OMEGA_STATE,
    SENSOR_NAMES,
    THETA_STATE,
)
from pmdcid.simulate.sensors import apply_sensors  # noqa: E402
from pmdcid.simulate.substeps import choose_substeps  # noqa: E402


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

    def __repr__(self) -> str:
        from pmdcid.io.plot import describe

        spans = "; ".join(f"{n} {np.nanmin(a):.4g}..{np.nanmax(a):.4g} {u}"
                          for n, a, u in (("omega", self.omega, "rad/s"), ("i", self.i, "A"))
                          if len(a) and np.isfinite(a).any())
        return f"SimResult({describe(self.t)}; {spans})"

    def plot(self, log=None):
        """The simulated current, speed and angle against time (matplotlib Figure); with
        ``log`` (the :class:`~pmdcid.io.Log` it was simulated on) its input on top and its
        measurements drawn beside the model's."""
        from pmdcid.io.plot import plot_columns

        sim = {n: a for n, a in (("i", self.i), ("omega", self.omega), ("theta", self.theta))
               if np.isfinite(a).any()}
        if log is None:
            return plot_columns(self.t, sim, "simulated")
        meas = {c: a for c, a in log.data.items() if c in sim or c == log.drive}
        return plot_columns(log.t, meas, "measured", styles={"model": sim})

    def to_pandas(self):
        """A DataFrame of t [s], i [A], omega [rad/s], theta [rad] (as the sensors read them)."""
        import pandas as pd

        return pd.DataFrame({"t": self.t, "i": self.i, "omega": self.omega,
                             "theta": self.theta})


#: static friction [N m] that holds a blocked rotor: "infinite", beyond any torque a log reaches
BLOCKED_BC = 1e300


def blocked_rotor(vals: dict[str, float]) -> dict[str, float]:
    """``vals`` with the rotor held still, as on a blocked-rotor log: infinite static friction
    (bc = :data:`BLOCKED_BC`) and LuGre off (the rotor is held by stiction, not by bristles)."""
    return {**vals, "bc": BLOCKED_BC, "sigma0": 0.0}


def neutral_values() -> dict[str, float]:
    """Every kernel and sensor parameter at the value that switches its effect off."""
    vals = {n: BASE_PARAMS[n].neutral for n in BASE_PARAMS}
    for eff in EFFECTS.values():
        for ps in eff.params:
            vals[ps.name] = ps.neutral
    # a lumped model's back-EMF share only where the model has one: with it and no lag the
    # current is instant (model.lumped.kernel_values); a lag without one takes the share as 1
    vals["ke_share"] = math.nan
    return vals


def param_values(model: Model, torque_driven: bool = False,
                 overrides: dict[str, float] | None = None) -> dict[str, float]:
    """Effective parameter values for simulation (SI), effects not in the model neutral.

    ``bv`` falls back to the paper's linear ``b`` when the nonlinear stage has not run yet.
    For torque-driven logs and lumped models R, L and km are not needed (a lumped model's
    electrical parameters are ignored: its input is the voltage, taken as the torque input).
    """
    lumped = is_lumped(model)
    torque_driven = torque_driven or lumped
    vals = neutral_values()
    active = {p.name for e in model.effects for p in EFFECTS[e].params}
    for name, par in model.parameters.items():
        if (name in BASE_PARAMS or name in active) and not (lumped and name in ELECTRICAL):
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
                    torque_driven: bool = False, nsub: int | None = None,
                    x0=None, out: np.ndarray | None = None, *,
                    dt: float | None = None, within: np.ndarray | None = None) -> SimResult:
    """Simulate with parameter values ``vals`` (see :func:`param_values`) from ``x0`` =
    (i [A], omega [rad/s], theta [rad]) at ``t[0]`` (default: rest; effect states such as
    LuGre's bristle deflection start at 0 unless a full state vector is given).

    ``out``: the kernel's state buffer (:func:`pmdcid.simulate.kernel.run_kernel`), reused by
    a caller that simulates the same log many times; the result's arrays may be views of it,
    valid until the next call with the same buffer. ``dt``: the sample period [s] (default:
    from ``t``); a caller simulating the first samples of a log passes the whole log's, so
    that the states are bit for bit the first ones of the whole log's simulation.
    ``within``: the input inside each sample, ``len(within) // len(u)`` means per sample (a
    loop-timed log's, :meth:`pmdcid.io.Log.input_within`), stepped instead of ``u``."""
    t = np.asarray(t, dtype=float)
    if dt is None:
        dt = float((t[-1] - t[0]) / (len(t) - 1))
    measured_current = not torque_driven
    vals, torque_driven = kernel_values(vals, torque_driven)  # a lumped model's electrical lag
    p = param_vector(vals)
    if torque_driven != (not measured_current):  # mapped: steps that resolve the lag
        nsub = max(choose_substeps(dt, p) if nsub is None else nsub,
                   lag_substeps(dt, vals["L"]))
    x0 = settled_start(x0, float(u[0]) if len(u) else 0.0, p, torque_driven)
    latency = float(vals.get("latency", 0.0))
    # the input read between samples (drive.ramp_input): when a fit reads it, every value
    # (0 included) runs on the fine grid, so the cost is continuous in it
    ramp = vals.get("ramp")
    steps = choose_substeps(dt, p) if nsub is None else nsub
    fine, h, inner, q = read_input(u, dt, steps, latency,
                                   None if ramp is None else float(ramp), within)
    if q == 1:  # held on time: the caller's buffer serves
        x = run_kernel(u, dt, p, torque_driven, steps, x0, out)
    else:  # late, read between samples, or stepped inside them: on the finer grid
        x = run_kernel(fine, h, p, torque_driven, inner, x0)[::q]
    sensor = {n: vals.get(n, 0.0) for n in SENSOR_NAMES}
    w, theta = x[:, OMEGA_STATE], x[:, THETA_STATE]
    om, th = apply_sensors(t, w, theta, sensor)
    i = x[:, I_STATE] if measured_current else np.full(len(t), np.nan)
    return SimResult(t, i, om, th, w, theta)


def simulate(t: np.ndarray, u: np.ndarray, model: Model, torque_driven: bool = False,
             nsub: int | None = None, overrides: dict[str, float] | None = None,
             x0=None, *, within: np.ndarray | None = None) -> SimResult:
    """Simulate ``model`` under input ``u`` (V, or N m if ``torque_driven``; V for a lumped
    model) at ``t``, from ``x0`` = (i, omega, theta) (default rest); ``within``: see
    :func:`simulate_values`."""
    from pmdcid.simulate.substeps import bounded_for

    vals = param_values(model, torque_driven, overrides)
    with bounded_for(model.path):
        return simulate_values(t, u, vals, torque_driven, nsub, x0, within=within)


def simulate_log(log, model: Model, nsub: int | None = None,
                 overrides: dict[str, float] | None = None, x0=None) -> SimResult:
    """Simulate ``model`` on a :class:`~pmdcid.io.Log`'s input column (a lumped model takes
    the voltage through the kernel's torque path, see :mod:`pmdcid.model.lumped`)."""
    return simulate(log.t, log.u, model, input_is_torque(log, model), nsub, overrides, x0,
                    within=log.input_within())


def logs_for(logs, model: Model) -> list:
    """The logs as the kernel sees them for ``model``: for a lumped model, each voltage log
    becomes a view whose input column is ``tau`` (the voltage, in V); other logs unchanged."""
    if not is_lumped(model):
        return list(logs)
    return [lumped_view(lg) for lg in logs]


def lumped_view(log):
    """A voltage log seen as torque-driven (same arrays, ``tau`` = ``v``), marked lumped."""
    import dataclasses

    if "v" not in log.data:
        return log
    data = {("tau" if k == "v" else k): a for k, a in log.data.items() if k != "tau"}
    view = dataclasses.replace(log, data=data, meta={**log.meta, "lumped": "true"})
    view.derived = set(log.derived)
    return view


def input_is_torque(log, model: Model) -> bool:
    """True when the kernel takes the log's input as a torque: a ``tau`` log, or a voltage log
    simulated by a lumped (per-volt) model."""
    return log.drive == "tau" or is_lumped(model)


__all__ = [
    "BLOCKED_BC", "INDEX", "NAMES", "SimResult", "blocked_rotor", "choose_substeps",
    "input_is_torque", "logs_for", "neutral_values", "param_values", "param_vector", "run_kernel",
    "simulate", "simulate_log", "simulate_values",
]
