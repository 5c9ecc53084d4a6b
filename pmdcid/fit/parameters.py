"""One parameter set for every fit: name, value, bounds, vary, prior, scale and step.

lmfit's ``Parameters`` in spirit: a fit takes one :class:`Parameters` instead of parallel
keyword lists (start values, bounds, priors, finite-difference steps). The solver works on the
scaled vector ``z = x / scale`` (:mod:`pmdcid.fit.solver`): each parameter's scale is its
starting magnitude, or its typical size where it starts at 0 (:func:`~.solver.scale_of`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.solver import scale_of
from pmdcid.model.effects import bounds_of, unit_of

#: relative finite-difference step of a parameter unless it says otherwise
STEP = 1e-3


@dataclass
class Parameter:
    """One parameter of a fit [SI unit of ``name``]: its start (or fixed) ``value``, bounds,
    whether the fit moves it, a Gaussian ``prior`` (mean, std) from earlier data, its typical
    size where its value is 0 (``typical``), and its relative finite-difference ``step``."""

    name: str
    value: float
    lower: float = -math.inf
    upper: float = math.inf
    vary: bool = True
    prior: tuple[float, float] | None = None
    typical: float = 1.0
    step: float = STEP

    @property
    def has_prior(self) -> bool:
        """A prior with a positive, finite width."""
        return self.prior is not None and self.prior[1] > 0 and math.isfinite(self.prior[1])


class Parameters(dict):
    """name -> :class:`Parameter`, in the fit's order."""

    @classmethod
    def of(cls, names: Iterable[str], values: Mapping[str, float],
           bounds: Mapping[str, tuple[float, float]] | None = None,
           steps: Mapping[str, float] | None = None,
           priors: Mapping[str, tuple[float, float]] | None = None,
           typical: Mapping[str, float] | None = None) -> Parameters:
        """The parameters ``names`` starting at ``values`` (NaN where missing), within the
        catalogue's bounds unless ``bounds`` gives others; ``steps``, ``priors`` and ``typical``
        by name (defaults: :data:`STEP`, none, 1)."""
        out = cls()
        for n in names:
            lo, hi = (bounds or {}).get(n) or bounds_of(n)
            out[n] = Parameter(n, float(values.get(n, math.nan)), lo, hi,
                               prior=(priors or {}).get(n),
                               typical=(typical or {}).get(n, 1.0),
                               step=(steps or {}).get(n, STEP))
        return out

    def filled(self, values: Mapping[str, float]) -> Parameters:
        """A copy whose parameters without a finite value take it from ``values``."""
        return Parameters({n: replace(p, value=p.value if math.isfinite(p.value)
                                      else float(values.get(n, math.nan)))
                           for n, p in self.items()})

    def fix(self, name: str, value: float) -> None:
        """Hold ``name`` at ``value`` (a fixed parameter: not fitted, used as given)."""
        self[name] = Parameter(name, float(value), vary=False)

    @property
    def free(self) -> list[str]:
        return [n for n, p in self.items() if p.vary]

    def varying(self) -> list[Parameter]:
        return [p for p in self.values() if p.vary]

    def tighten(self, name: str, lower: float, upper: float) -> None:
        """Narrow ``name``'s bounds to ``[lower, upper]`` (never widen them)."""
        p = self[name]
        p.lower, p.upper = max(p.lower, lower), min(p.upper, upper)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper bounds of the varying parameters."""
        ps = self.varying()
        return np.array([p.lower for p in ps], float), np.array([p.upper for p in ps], float)

    def start(self) -> np.ndarray:
        """The varying parameters' values within their bounds; raises :class:`FitError` when
        one has no finite value."""
        ps = self.varying()
        bad = [p.name for p in ps if not math.isfinite(p.value)]
        if bad:
            raise FitError(f"no finite starting value for {', '.join(bad)}")
        empty = [p for p in ps if not p.lower < p.upper]
        if empty:
            p = empty[0]
            raise FitError(
                f"no room to fit {p.name}: the range the logs allow, narrowed to its physical "
                f"bounds, is empty ([{p.lower:.3g}, {p.upper:.3g}] {unit_of(p.name)}): check the "
                "units and scale of the logs' columns")
        lo, hi = self.bounds()
        return np.clip(np.array([p.value for p in ps], float), lo, hi)

    def scales(self, start: np.ndarray) -> np.ndarray:
        """The solver's scale of each varying parameter at ``start`` (:func:`scale_of`)."""
        return scale_of(start, np.array([p.typical for p in self.varying()], float))

    def steps(self) -> np.ndarray:
        return np.array([p.step for p in self.varying()], float)

    def prior_rows(self) -> list[tuple[int, float, float]]:
        """(index among the varying, mean, std) of each usable prior."""
        return [(j, *p.prior) for j, p in enumerate(self.varying()) if p.has_prior]


__all__ = ["STEP", "Parameter", "Parameters"]
