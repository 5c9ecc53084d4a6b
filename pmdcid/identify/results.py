"""Typed fit results: value, standard error, unit and fit statistics (not tuples)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.identify.covariance import CovarianceInfo


@dataclass
class Estimate:
    """One estimated parameter [unit], its standard error (NaN if unknown), whether it varied."""

    name: str
    value: float
    stderr: float = math.nan
    unit: str = ""
    vary: bool = True

    @property
    def rel_stderr(self) -> float:
        return abs(self.stderr / self.value) if self.value else math.nan

    def __str__(self) -> str:
        se = f" ± {self.stderr:.3g}" if math.isfinite(self.stderr) else ""
        return f"{self.name} = {self.value:.6g}{se} {self.unit}".rstrip()


@dataclass
class FitStats:
    """Statistics of a least-squares fit (lmfit's MinimizerResult vocabulary)."""

    ndata: int
    nvarys: int
    chisqr: float
    nfev: int = 0
    success: bool = True
    message: str = ""

    @property
    def nfree(self) -> int:
        return max(self.ndata - self.nvarys, 1)

    @property
    def redchi(self) -> float:
        return self.chisqr / self.nfree

    @property
    def aic(self) -> float:
        return self.ndata * math.log(max(self.chisqr, 1e-300) / self.ndata) + 2 * self.nvarys

    @property
    def bic(self) -> float:
        n = self.ndata
        return n * math.log(max(self.chisqr, 1e-300) / n) + math.log(n) * self.nvarys


@dataclass
class SimFitResult:
    """Result of a simulation-error fit: estimates, correlations, statistics, per-log errors."""

    estimates: dict[str, Estimate]
    stats: FitStats
    correl: dict[str, dict[str, float]] = field(default_factory=dict)
    nrmse: list[dict[str, float]] = field(default_factory=list)  # per log: signal -> NRMSE
    sigma: list[dict[str, float]] = field(default_factory=list)  # per log: signal -> weight std
    #: how the covariance allowed for correlated residuals (None: white-residual formula)
    covariance: CovarianceInfo | None = None
    #: per log: the state (i, omega, theta) it was simulated from (measured or fitted start)
    initial: list = field(default_factory=list)
    #: name -> (mean, std) of the Gaussian prior terms that entered the fit
    priors: dict = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.estimates.items()}

    def correlation(self, a: str, b: str) -> float:
        return self.correl.get(a, {}).get(b, math.nan)


def nrmse(sim: np.ndarray, meas: np.ndarray) -> float:
    """RMS error divided by the standard deviation of the measurement (CONTRACT.md)."""
    ok = np.isfinite(sim) & np.isfinite(meas)
    if ok.sum() < 2:
        return math.nan
    sd = float(np.std(meas[ok]))
    err = float(np.sqrt(np.mean((sim[ok] - meas[ok]) ** 2)))
    return err / sd if sd > 0 else math.inf
