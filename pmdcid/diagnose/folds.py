"""Which data diagnose fits and which it holds out: repeats of one protocol, held out whole.

Logs named like ``step_1.csv .. step_6.csv`` (a stem ending in ``_N``) whose inputs agree are
*repeats* of one protocol. When the logs hold repeats, the last repeat of each protocol is held
out whole: an effect is kept only when it predicts a run it was never fitted on, which is the
question a user asks of a model, and a step's plateau is never compared with its transient.
A log without a repeat is split in time (its first ``split`` fitted, the rest held out): holding
it out whole would take its excitation (often the only triangle or staircase) out of the fit.

Repeats also give the *repeatability floor*: how far each run lies from the mean of the other
runs of its protocol (speed NRMSE). No model of the rig can predict a run better than the rig
repeats itself, so diagnose does not chase structure below that floor.
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: inputs of two runs agree when their RMS difference is under this share of the input's std
SAME_INPUT = 0.05
#: durations of repeats agree within this share
SAME_LENGTH = 0.1
LOG_EXTENSIONS = (".csv", ".txt", ".tsv", ".dat")
_TRAILING = re.compile(r"^(.*?)[_-]?(\d+)$")


def protocol_key(path: str) -> str:
    """A log's protocol name: its file stem without a trailing run number (``step_3`` ->
    ``step``; ``step_6V_2`` -> ``step_6V``; ``triangle`` -> ``triangle``)."""
    stem, ext = os.path.splitext(os.path.basename(path or ""))
    if ext.lower() not in LOG_EXTENSIONS:
        stem += ext  # "step_1.0V" has no extension
    m = _TRAILING.match(stem)
    return m.group(1) if m and m.group(1) else stem


def onset(log) -> float:
    """Time [s] of the input's first change (10 % of its range away from its first value)."""
    u = np.asarray(log.u, float)
    moved = np.abs(u - u[0]) > 0.1 * max(float(np.ptp(u)), 1e-300)
    return float(log.t[int(np.argmax(moved))]) if moved.any() else float(log.t[0])


def _on_common_time(a, b, xa, xb) -> tuple[np.ndarray, np.ndarray]:
    """``xa`` and ``xb`` (signals of logs a and b) at a's samples within both logs' time span,
    b shifted so that the inputs' first changes coincide (a run started a little earlier or
    later, or whose first samples were trimmed, is still a repeat)."""
    ta = np.asarray(a.t, float)
    tb = np.asarray(b.t, float) + onset(a) - onset(b)
    m = (ta >= tb[0]) & (ta <= tb[-1])
    return np.asarray(xa, float)[m], np.interp(ta[m], tb, np.asarray(xb, float))


def _same_input(a, b) -> bool:
    if a.drive != b.drive:
        return False
    if abs(a.duration - b.duration) > SAME_LENGTH * max(a.duration, b.duration):
        return False
    ua, ub = _on_common_time(a, b, a.u, b.u)
    if len(ua) < 0.5 * a.n:
        return False
    scale = max(float(np.std(ua)), float(np.std(ub)), 1e-300)
    return float(np.sqrt(np.mean((ua - ub) ** 2))) <= SAME_INPUT * scale


def repeat_groups(logs: Sequence) -> list[list[int]]:
    """Groups (indices, in order) of two or more logs that repeat one protocol: the same
    protocol name and the same input (:data:`SAME_INPUT`, :data:`SAME_LENGTH`)."""
    by_key: dict[str, list[int]] = {}
    for k, log in enumerate(logs):
        by_key.setdefault(protocol_key(log.path), []).append(k)
    out = []
    for idx in by_key.values():
        rest = list(idx)
        while rest:
            head, rest = rest[0], rest[1:]
            grp = [head] + [k for k in rest if _same_input(logs[head], logs[k])]
            rest = [k for k in rest if k not in grp]
            if len(grp) >= 2:
                out.append(grp)
    return out


def holdout_plan(logs: Sequence) -> list[str]:
    """Per log: ``"held"`` (held out whole: the last repeat of a protocol), ``"fit"`` (another
    repeat: fitted whole) or ``"split"`` (no repeat: split in time)."""
    plan = ["split"] * len(logs)
    for grp in repeat_groups(logs):
        for k in grp:
            plan[k] = "fit"
        plan[grp[-1]] = "held"
    return plan


@dataclass
class Floor:
    """The repeatability floor of one protocol: speed NRMSE of each run against the mean of
    the other runs (RMS difference / std of the run)."""

    protocol: str
    logs: list[str]
    nrmse: list[float]

    @property
    def value(self) -> float:
        return float(np.mean(self.nrmse)) if self.nrmse else math.nan

    def to_json(self) -> dict:
        return {"protocol": self.protocol, "logs": self.logs, "omega_nrmse": self.nrmse,
                "floor": self.value}


def repeatability(logs: Sequence, signal: str = "omega") -> list[Floor]:
    """The floor of every repeated protocol whose logs measure ``signal`` (each run at the first
    run's time stamps, inputs' first changes aligned, within the span all runs cover)."""
    out = []
    for grp in repeat_groups(logs):
        runs = [k for k in grp if logs[k].has(signal)]
        if len(runs) < 2:
            continue
        ref = logs[runs[0]]
        t = np.asarray(ref.t, float)
        shift = {k: onset(ref) - onset(logs[k]) for k in runs}
        m = np.ones(len(t), bool)
        for k in runs:
            m &= (t >= logs[k].t[0] + shift[k]) & (t <= logs[k].t[-1] + shift[k])
        ys = np.array([np.interp(t[m], np.asarray(logs[k].t) + shift[k],
                                 np.asarray(logs[k][signal], float)) for k in runs])
        vals = []
        for j in range(len(runs)):
            other = np.mean(np.delete(ys, j, axis=0), axis=0)
            sd = float(np.std(ys[j]))
            vals.append(float(np.sqrt(np.mean((ys[j] - other) ** 2)) / sd) if sd > 0 else 0.0)
        out.append(Floor(protocol_key(logs[runs[0]].path), [logs[k].path for k in runs], vals))
    return out


def floor_of(floors: Sequence[Floor]) -> float | None:
    """The pooled floor (mean over protocols), None without repeats."""
    v = [f.value for f in floors if math.isfinite(f.value)]
    return float(np.mean(v)) if v else None


__all__ = ["Floor", "floor_of", "holdout_plan", "protocol_key", "repeat_groups",
           "repeatability"]
