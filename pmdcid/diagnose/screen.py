"""Cheap screening: regress the residual on each effect's simulated signature.

For an effect, each probe column (its parameters switched on slightly, see its module in
:mod:`pmdcid.model.effects`) is simulated on every log; the weighted change of the simulated
signals is one regressor. The residual (fit part) is regressed on the effect's columns together
with the sensitivities to the refitted base parameters (which may have absorbed part of it:
``Effect.interacts`` names the usual suspects, all are included); the drop in the residual sum of
squares over the base parameters alone is the
effect's *screening gain* (a linearised likelihood-ratio statistic), and the coefficients give the
refit's starting point through the effect's ``guess``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.fit.problem import Problem, refit_range
from pmdcid.model.effects import Effect
from pmdcid.model.residual import ResidualContext
from pmdcid.runtime.cpus import pmap

#: relative step of a base parameter's sensitivity column
BASE_STEP = 0.05


@dataclass
class Screen:
    """One effect's screening: gain (chi-square drop), its best probe, the starting values."""

    effect: str
    gain: float
    label: str = ""
    start: dict[str, float] | None = None
    approx_delta_bic: float = math.inf
    #: the base parameters moved as the same regression moves them along with the effect (the
    #: linearised joint step): a refit started from the effect alone on a model whose bc or bv
    #: had absorbed part of it starts far uphill (10x the chi-square on the demo logs)
    base: dict[str, float] = field(default_factory=dict)


def _rss(x: np.ndarray | None, r: np.ndarray) -> tuple[float, np.ndarray]:
    if x is None or x.shape[1] == 0:
        return float(r @ r), np.zeros(0)
    coef, *_ = np.linalg.lstsq(x, r, rcond=None)
    e = r - x @ coef
    return float(e @ e), coef


def feasible_step(vals: dict[str, float], target: dict[str, float]) -> dict[str, float]:
    """The linearised joint step from ``vals`` to ``target`` (base parameters), shortened as a
    whole to stay where the refit may start (:func:`~pmdcid.fit.problem.refit_range`): the
    regression's step is a straight line through the sensitivities, and beyond that range it is
    no longer a step the simulation can take (test_back_emf_found_on_logs_with_current: R
    38 -> -290 ohm with L x33, a growing armature current, the residual overflowing 1e308).
    A parameter already at its bound (bc = 0) is held there, not the whole step."""
    frac = 1.0
    ranges = {p: refit_range(p, vals[p]) for p in target}
    for p, x in target.items():
        v, (lo, hi) = vals[p], ranges[p]
        if x < lo < v or x > hi > v:
            frac = min(frac, ((lo if x < lo else hi) - v) / (x - v))
    return {p: min(max(vals[p] + frac * (x - vals[p]), ranges[p][0]), ranges[p][1])
            for p, x in target.items()}


class Screener:
    """Screens effects against one model state (values ``vals``) on a :class:`Problem`."""

    def __init__(self, problem: Problem, vals: dict[str, float], ctx: ResidualContext,
                 base_free: list[str]):
        self.problem = problem
        self.vals = vals
        self.ctx = ctx
        self.base_free = base_free
        self.r0 = problem.weighted(problem.simulate_all(vals, "fit"), "fit")
        self.chi2 = float(self.r0 @ self.r0)
        self.n = len(self.r0)
        self._base_cols: dict[str, np.ndarray | None] = {}

    def column(self, overrides: dict[str, float]) -> np.ndarray:
        """Weighted change of the residual when ``overrides`` are applied, sign flipped
        (``r0 - r``: minus the change of the simulated signals): regressing ``r0`` on such
        columns gives the fraction of each override that removes the residual."""
        sims = self.problem.simulate_all({**self.vals, **overrides}, "fit")
        return self.r0 - self.problem.weighted(sims, "fit")

    def base_step(self, name: str) -> float:
        """The step [unit of ``name``] of a base parameter's sensitivity column (0: none)."""
        v = self.vals.get(name, 0.0)
        if v != 0.0 and math.isfinite(v):
            return BASE_STEP * abs(v)
        return BASE_STEP * self.ctx.torque_scale if name in ("bc", "dz") else 0.0

    def base_column(self, name: str) -> np.ndarray | None:
        if name not in self._base_cols:
            v = self.vals.get(name, 0.0)
            step = self.base_step(name)
            col = self.column({name: v + step}) if step > 0 else None
            if col is not None and not np.any(col):
                col = None
            self._base_cols[name] = col
        return self._base_cols[name]

    def screen(self, effect: Effect) -> Screen:
        """Best probe of ``effect``: gain over its interacting base parameters alone."""
        best = Screen(effect.name, 0.0)
        if effect.signature is None or effect.guess is None:
            return best
        names = [p for p in self.base_free if self.base_column(p) is not None]
        inter = [self.base_column(p) for p in names]
        d = np.column_stack(inter) if inter else None
        rss_d, _ = _rss(d, self.r0)
        for probe in effect.signature(self.ctx):
            cols = pmap(self.column, probe.columns)
            if not any(np.any(c) for c in cols):
                continue
            x = np.column_stack(cols + inter)
            rss, coef = _rss(x, self.r0)
            gain = rss_d - rss
            if not gain > best.gain:
                continue
            start = effect.guess(probe, coef[: len(cols)], self.ctx)
            if start is None:
                continue
            k = len(effect.params) - len(effect.held)
            dbic = self.n * math.log(max(rss, 1e-300) / max(rss_d, 1e-300)) + k * math.log(self.n)
            base = feasible_step(self.vals, {
                p: self.vals[p] + float(c) * self.base_step(p)
                for p, c in zip(names, coef[len(cols):], strict=True)})
            best = Screen(effect.name, gain, probe.label, start, dbic, base)
        return best


__all__ = ["Screen", "Screener", "feasible_step"]
