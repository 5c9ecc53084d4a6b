"""Simulate a model on a log's input and compare with what the log measured."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import LogError
from pmdcid.model import Model
from pmdcid.report.metrics import lag_step_for, signal_metrics, speed_threshold
from pmdcid.simulate import SimResult
from pmdcid.simulate.measured import compared_signals, simulate_for, values_for

#: signals compared, in display order, with their units
SIGNALS = {"omega": "rad/s", "theta": "rad", "i": "A"}


@dataclass
class LogComparison:
    """One log against the model: the simulation, the regime mask and every number."""

    name: str
    log: object
    sim: SimResult
    blocked: bool
    signals: list[str]
    low: np.ndarray | None  # near-zero-speed samples (None without a speed)
    threshold: float | None  # |omega| threshold of the near-zero regime [rad/s]
    metrics: dict


def figure_view(cmp: LogComparison) -> tuple[LogComparison, int]:
    """A copy of ``cmp`` holding only what the figures draw (the columns compared, the speed,
    the input; the sensor-read simulation), to send to a figure worker; and its number of
    array elements. The figures drawn from it are those drawn from ``cmp``."""
    import dataclasses

    log = cmp.log
    keep = {*cmp.signals, log.drive, *(["omega"] if log.has("omega") else [])}
    slim = dataclasses.replace(log, data={c: log[c] for c in log.data if c in keep}, extra={},
                               t_file=None, skipped={}, issues=[])
    none = np.empty(0)  # the rotor's own speed and angle: not drawn
    sim = SimResult(cmp.sim.t, cmp.sim.i, cmp.sim.omega, cmp.sim.theta, none, none)
    size = len(log.t) * (2 + len(slim.data) + 3)
    return dataclasses.replace(cmp, log=slim, sim=sim, low=None), size


def start_of(sim: SimResult) -> dict:
    """The state a simulation started from (its first sample): i [A] (None for a torque-driven
    one), the rotor's omega [rad/s] and theta [rad]."""
    i0 = float(sim.i[0])
    return {"i": i0 if math.isfinite(i0) else None, "omega": float(sim.omega_true[0]),
            "theta": float(sim.theta_true[0])}


def logged_units(log, signals) -> dict:
    """Per canonical column the log held in its own unit (``Log.sources``): the source column
    and its scale and offset to SI (SI = logged x scale + offset)."""
    cols = [*signals, log.drive]
    return {c: {"source": src, "scale": k, "offset": b}
            for c, (src, k, b) in getattr(log, "sources", {}).items() if c in cols and k != 0}


def compare_log(log, model: Model, name: str) -> LogComparison:
    """Simulate and compute the metrics of :mod:`pmdcid.report.metrics` for every signal."""
    if log.n < 4:
        raise LogError(f"has only {log.n} samples: too short to compare", log.path)
    signals = compared_signals(log, model)
    sim = simulate_for(log, model)
    blocked = log.blocked
    low = threshold = None
    if log.has("omega") and not blocked:
        threshold = speed_threshold(log["omega"])
        low = np.abs(log["omega"]) < threshold
    step = lag_step_for(values_for(log, model), log.dt, electrical=blocked)
    per = {}
    for s in signals:
        simv = sim.get(s)
        if not np.all(np.isfinite(simv)):
            raise LogError(f"the model's simulated {s} is not finite on this log "
                           "(check the model's parameters)", log.path)
        per[s] = signal_metrics(simv, log[s], log.u, low, step)
        per[s]["unit"] = SIGNALS[s]
        per[s]["derived"] = s in getattr(log, "derived", set())
    units = logged_units(log, signals)
    for s, lu in units.items():
        if s in per and per[s]["rms"] is not None:
            per[s]["rms_logged"] = per[s]["rms"] / abs(lu["scale"])
    m = {
        "name": name, "path": str(log.path), "kind": log.kind, "drive": log.drive,
        "n": int(log.n), "dt": float(log.dt), "rate_hz": 1.0 / float(log.dt),
        "duration": float(log.duration),
        "blocked": blocked, "omega_threshold": threshold, "signals": per,
        "initial_state": start_of(sim),
        "logged_units": units,
    }
    return LogComparison(name, log, sim, blocked, signals, low, threshold, m)


def model_errors(logs, model: Model) -> list[dict[str, float | None]]:
    """Per log: signal -> NRMSE of ``model`` (for the before/after comparison)."""
    out = []
    for log in logs:
        sim = simulate_for(log, model)
        row = {}
        for s in compared_signals(log, model):
            sd = float(np.std(log[s]))
            e = float(np.sqrt(np.mean((sim.get(s) - log[s]) ** 2)))
            v = e / sd if sd > 0 else math.nan
            row[s] = v if math.isfinite(v) else None
        out.append(row)
    return out


def mean_errors(rows: list[dict]) -> dict[str, float | None]:
    """Mean NRMSE per signal over the logs that carry it, keyed ``<signal>_nrmse``."""
    out = {}
    for s in SIGNALS:
        vals = [r[s] for r in rows if r.get(s) is not None]
        if vals:
            out[f"{s}_nrmse"] = float(np.mean(vals))
    return out
