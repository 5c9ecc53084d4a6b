"""Repeated measurement: median, min and max of several runs, within a time budget."""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class Stats:
    """Summary of repeated measurements of one figure (seconds, bytes, ... as measured)."""

    values: list[float] = field(default_factory=list)
    #: CPU seconds of each run (this process's, or the child's), when measured
    cpu: list[float] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.values)

    @property
    def median(self) -> float:
        return statistics.median(self.values) if self.values else math.nan

    @property
    def min(self) -> float:
        return min(self.values) if self.values else math.nan

    @property
    def max(self) -> float:
        return max(self.values) if self.values else math.nan

    @property
    def cpu_median(self) -> float:
        return statistics.median(self.cpu) if self.cpu else math.nan

    def scaled(self, factor: float) -> Stats:
        """The same runs multiplied by ``factor`` (e.g. seconds -> ns per step)."""
        return Stats([v * factor for v in self.values], [c * factor for c in self.cpu])

    def extend(self, other: Stats) -> None:
        self.values += other.values
        self.cpu += other.cpu


def measure(fn: Callable[[], object], repeat: int = 5, budget_s: float = 30.0,
            warmup: int = 1, min_runs: int = 1) -> Stats:
    """Wall-clock seconds of ``fn()`` over up to ``repeat`` runs after ``warmup`` untimed runs.

    Stops early once ``budget_s`` seconds have been spent on timed runs and at least
    ``min_runs`` are done, so that a slow row cannot blow the total time of ``make bench``.
    """
    for _ in range(warmup):
        fn()
    out = Stats()
    spent = 0.0
    for _ in range(repeat):
        c0 = time.process_time()  # every thread's: the fits compute on several
        t0 = time.perf_counter()
        fn()
        dt = time.perf_counter() - t0
        out.cpu.append(time.process_time() - c0)
        out.values.append(dt)
        spent += dt
        if spent >= budget_s and out.n >= min_runs:
            break
    return out


def collect(fn: Callable[[], float | tuple[float, float]], repeat: int = 3,
            budget_s: float = 60.0, min_runs: int = 1) -> Stats:
    """Values returned by ``fn()`` (it measures itself, e.g. a subprocess) over several runs;
    ``fn`` may return (value, cpu seconds)."""
    out = Stats()
    t_start = time.perf_counter()
    for _ in range(repeat):
        got = fn()
        if isinstance(got, tuple):
            out.values.append(float(got[0]))
            out.cpu.append(float(got[1]))
        else:
            out.values.append(float(got))
        if time.perf_counter() - t_start >= budget_s and out.n >= min_runs:
            break
    return out


def interleaved(fns: dict[str, Callable[[], object]], rounds: int = 10, inner: int = 1,
                budget_s: float = 30.0, warmup: int = 1) -> dict[str, Stats]:
    """Seconds per call of several functions measured in turns (round-robin), so that a burst
    of load from other processes falls on all of them alike and their ratios hold.

    Each round calls every function ``inner`` times in a row and records the mean of those.
    """
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    out = {k: Stats() for k in fns}
    t_start = time.perf_counter()
    for _ in range(rounds):
        for k, fn in fns.items():
            c0 = time.thread_time()
            t0 = time.perf_counter()
            for _ in range(inner):
                fn()
            out[k].values.append((time.perf_counter() - t0) / inner)
            out[k].cpu.append((time.thread_time() - c0) / inner)
        if time.perf_counter() - t_start >= budget_s:
            break
    return out
