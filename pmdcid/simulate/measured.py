"""A model against a log, as the log's sensors measured it: the simulation from the state the
log's first samples measured (a blocked rotor held still), the signals the model predicts, and
the rows a quick figure of a fit draws (``result.plot()``, :mod:`pmdcid.io.plot`). The report
(:mod:`pmdcid.report.compare`) and ``plan --check`` simulate logs with the same functions."""

from __future__ import annotations

import numpy as np

from pmdcid.errors import LogError, PmdcidError, one_line
from pmdcid.model import Model
from pmdcid.model.lumped import is_lumped
from pmdcid.simulate import (
    SimResult,
    blocked_rotor,
    input_is_torque,
    param_values,
    simulate_values,
)
from pmdcid.simulate.initial import initial_state, true_start


def values_for(log, model: Model) -> dict[str, float]:
    """The simulation values of ``model`` on ``log`` (:func:`~pmdcid.simulate.param_values`);
    a rotor held still needs no inertia and no torque constant, so fit-electrical's R and L
    alone simulate a blocked-rotor log's current (J and km stand at 1 there, unused)."""
    held = {n: 1.0 for n in ("J", "km") if log.blocked and not model.has(n)}
    return param_values(model, input_is_torque(log, model), held or None)


def simulate_for(log, model: Model) -> SimResult:
    """Simulate ``model`` on the log's input from the state its first samples measured
    (:mod:`pmdcid.simulate.initial`: rest unless it starts turning); a blocked rotor is held
    still; a lumped model takes the voltage through the torque path."""
    torque = input_is_torque(log, model)
    blocked = log.blocked
    vals = values_for(log, model)
    if blocked:
        vals = blocked_rotor(vals)
    x0 = true_start(initial_state(log), vals)
    if blocked:
        x0[1] = 0.0
    return simulate_values(log.t, log.u, vals, torque, x0=x0, within=log.input_within())


def predicts_current(model: Model | None) -> bool:
    """A lumped (per-volt) model simulates no current: a log's current is not compared with it.
    Before, a log with a current column (a lab rig's, identified without --km beside
    blocked-rotor steps) stopped report, and identify -o after all its fits, with 'the model's
    simulated i is not finite on this log'."""
    return model is None or not is_lumped(model)


def compared_signals(log, model: Model | None = None) -> list[str]:
    """The measured signals the model predicts: speed and angle (not for a blocked rotor), and
    current unless the log is torque-driven or the model lumped (:func:`predicts_current`)."""
    blocked = log.blocked
    out = [s for s in ("omega", "theta") if log.compares(s) and not blocked]
    if log.compares("i") and predicts_current(model):
        out.append("i")
    if not out:
        raise LogError("has nothing to compare the model with: it needs omega, theta or "
                       "(voltage-driven) i", log.path)
    return out


def fit_rows(logs, model: Model) -> tuple[list[tuple], list[str]]:
    """What a quick figure of a fit draws: per log that the model predicts, (name, t [s],
    signal, measured, simulated) for its first compared signal (the speed, or a blocked
    rotor's current); and the names of the logs left out, with why (nothing the model
    predicts, or a model that cannot simulate the log: a stage's result alone)."""
    rows, left = [], []
    for log in logs:
        name = str(log.path)
        try:
            signal = compared_signals(log, model)[0]
            sim = simulate_for(log, model)
        except PmdcidError as exc:  # nothing to compare, or the model cannot simulate it
            left.append(f"{name} ({one_line(str(exc))[:120]})")
            continue
        rows.append((name, log.t, signal, np.asarray(log[signal], float), sim.get(signal)))
    return rows, left


__all__ = ["compared_signals", "fit_rows", "predicts_current", "simulate_for", "values_for"]
