"""Synthetic fleets with known truth, for the tests, ``make fleetbench`` and docs/fleet.md.

Every unit is the paper's motor (:data:`pmdcid.synth.PAPER`) with a manufacturing spread, put
through an end-of-line test: a blocked-rotor pulse (5 kHz), two speed steps and a triangle
(500 Hz), written as CSV logs with ``pmdcid.synth`` (the simulation kernel and its noise
model); ``rng`` is a ``numpy.random.Generator`` passed in. Some units are outliers (one
parameter off by a factor), some are measured again later, drifting (parameters multiplied) or
not.
"""

from __future__ import annotations

import csv
import json
import os
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone

import numpy as np

from pmdcid.synth import PAPER, PAPER_NOISE, NoiseSpec, step, synth_log, triangle

#: parameters with a manufacturing spread (km is the datasheet's, shared by all units)
SPREAD_PARAMS = ("R", "L", "J", "bv", "bc", "dz")
#: when the first measurements were taken
START = datetime(2026, 3, 2, 8, 0, tzinfo=timezone.utc)


@dataclass
class Protocol:
    """The end-of-line test: durations [s], rates [Hz], amplitudes [V]."""

    blocked_s: float = 0.2
    blocked_rate: float = 5000.0
    step_s: float = 2.0
    steps_v: tuple[float, ...] = (1.0, 2.0)
    triangle_s: float = 15.0
    triangle_v: float = 2.0
    triangle_period: float = 7.5
    rate: float = 500.0
    noise: NoiseSpec = PAPER_NOISE


@dataclass
class FleetSpec:
    """A fleet: ``units`` units, relative spread ``spread`` (std) of :data:`SPREAD_PARAMS`,
    ``outliers`` {unit index: (parameter, factor)}, ``drifting`` {unit index: {parameter:
    factor}} (measured again ``days`` later with those changes), ``repeated``: unit indices
    measured again unchanged."""

    units: int = 8
    spread: float = 0.05
    outliers: dict[int, tuple[str, float]] = field(default_factory=dict)
    drifting: dict[int, dict[str, float]] = field(default_factory=dict)
    repeated: tuple[int, ...] = ()
    days: float = 30.0
    protocol: Protocol = field(default_factory=Protocol)


def unit_truths(spec: FleetSpec, rng: np.random.Generator) -> list[dict[str, float]]:
    """Each unit's true parameters (SI): the paper's, spread, outliers applied."""
    from pmdcid.simulate import neutral_values

    out = []
    for k in range(spec.units):
        vals = {**neutral_values(), **PAPER}
        for p in SPREAD_PARAMS:
            vals[p] = PAPER[p] * (1.0 + spec.spread * float(rng.standard_normal()))
        if k in spec.outliers:
            p, factor = spec.outliers[k]
            vals[p] *= factor
        out.append(vals)
    return out


def unit_logs(folder: str, vals: dict[str, float], proto: Protocol,
              rng: np.random.Generator) -> list[str]:
    """Write one measurement's logs (module doc) into ``folder``; returns their paths."""
    from pmdcid.io import write_log

    os.makedirs(folder, exist_ok=True)
    paths = []
    tb = np.arange(int(round(proto.blocked_s * proto.blocked_rate))) / proto.blocked_rate
    cols, _ = synth_log(tb, step(tb, 2.0, 0.1 * proto.blocked_s), vals, proto.noise, rng,
                        blocked=True)
    paths.append(_write(write_log, folder, "blocked.csv", tb, cols, "blocked-rotor"))
    ts = np.arange(int(round(proto.step_s * proto.rate))) / proto.rate
    for a in proto.steps_v:
        cols, _ = synth_log(ts, step(ts, a, 0.1 * proto.step_s), vals, proto.noise, rng)
        paths.append(_write(write_log, folder, f"step_{a:g}V.csv", ts, cols, "free-speed-step"))
    if proto.triangle_s > 0:
        tt = np.arange(int(round(proto.triangle_s * proto.rate))) / proto.rate
        cols, _ = synth_log(tt, triangle(tt, proto.triangle_v, proto.triangle_period), vals,
                            proto.noise, rng)
        paths.append(_write(write_log, folder, "triangle.csv", tt, cols, "triangle"))
    return paths


def _write(write_log, folder, name, t, cols, kind) -> str:
    path = os.path.join(folder, name)
    write_log(path, t, cols, {"generator": "pmdcid", "kind": kind})
    return path


def write_fleet(folder: str, spec: FleetSpec, rng: np.random.Generator) -> tuple[str, list]:
    """Write a fleet's logs and ``folder/manifest.csv``; returns (manifest path, truth), truth
    being one ``{"unit", "time", "batch", "params"}`` per measurement, in manifest order."""
    rows, truth = [], []
    for k, vals in enumerate(unit_truths(spec, rng)):
        unit = f"M{k + 1:03d}"
        times = [(START + timedelta(hours=k), vals)]
        if k in spec.drifting or k in spec.repeated:
            later = {p: v * spec.drifting.get(k, {}).get(p, 1.0) for p, v in vals.items()}
            times.append((START + timedelta(days=spec.days, hours=k), later))
        for j, (when, v) in enumerate(times):
            sub = os.path.join(folder, unit, f"m{j}")
            for p in unit_logs(sub, v, spec.protocol, rng):
                rows.append([unit, os.path.relpath(p, folder), when.isoformat(), f"B{k // 8}"])
            truth.append({"unit": unit, "time": when.isoformat(), "batch": f"B{k // 8}",
                          "params": {p: v[p] for p in (*SPREAD_PARAMS, "km")}})
    manifest = os.path.join(folder, "manifest.csv")
    with open(manifest, "w", newline="") as fh:
        w = csv.writer(fh, lineterminator="\n")
        w.writerow(["unit", "log", "time", "batch"])
        w.writerows(rows)
    with open(os.path.join(folder, "truth.json"), "w") as fh:
        json.dump({"spec": {"units": spec.units, "spread": spec.spread,
                            "outliers": {str(k): v for k, v in spec.outliers.items()},
                            "drifting": {str(k): v for k, v in spec.drifting.items()}},
                   "measurements": truth}, fh, indent=1)
    return manifest, truth


__all__ = ["FleetSpec", "Protocol", "unit_logs", "unit_truths", "write_fleet"]
