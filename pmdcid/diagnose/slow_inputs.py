"""A slowly logged, continuously varying input in diagnose: read between its samples as
fit-nonlinear reads it (:mod:`pmdcid.identify.ramp_profile`).

Read as held (docs/io.md's zero-order hold), a continuous command logged slowly acts half a
sample late; where the sample period is not small against J/bv, a refit turns that lag into a
wrong inertia, and the search turns it into an effect nobody has (on the paper's motor with its
triangle logged at 10 Hz, diagnose added ``input_delay`` and rewrote J). The logs where the
reading matters (:func:`pmdcid.identify.identifiability.hold_matters`) are simulated with the
input read at ``ramp`` (0 held, 1 straight to the next sample; the other logs stay held): the
value identify's joint fit found when it is given (0, held, when it read none: its J came
from the steps), else a profile of the base refit over
:data:`pmdcid.identify.ramp_profile.RAMPS`, as fit-nonlinear does.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.identify.identifiability import hold_matters
from pmdcid.identify.ramp_profile import RAMPS, parabola_minimum


def slow_logs(problem, vals: dict[str, float]) -> list[int]:
    """Logs of ``problem`` whose input reading moves the inertia at ``vals`` (J, bv)."""
    J, bv = vals.get("J", math.nan), vals.get("bv", math.nan)
    return [k for k, lg in enumerate(problem.logs)
            if not problem.blocked[k] and hold_matters(lg, J, bv)]


def read_slow_inputs(run, ramp: float | None, notes: list[str]) -> None:
    """Set how the slow logs' inputs varied between samples (``ramp`` when given, else
    profiled); a note says which logs and what reading. Nothing when no log is slow or
    ``ramp`` is 0 (held, as the logs are read by default)."""
    problem = run.problem
    slow = slow_logs(problem, run.vals0)
    if not slow or ramp == 0.0:  # 0: held, the contract's reading
        return
    how = "identify's joint fit"
    if ramp is None or not math.isfinite(ramp):
        ramp, se = _profile(run, slow)
        how = f"a profile of the base refit (± {se:.2g})"
    problem.set_readings({k: float(ramp) for k in slow})
    run.refresh()
    names = ", ".join(problem.logs[k].path for k in slow)
    notes.append(f"slowly logged inputs ({names}): read between samples at ramp = {ramp:.2g} "
                 f"(0: held, 1: straight to the next sample), from {how}; read as held they "
                 "would bias J and pass for an input delay")


def _profile(run, slow: list[int]) -> tuple[float, float]:
    """(ramp, its standard error): the base refit's fit-part chi-square at each of RAMPS."""
    chi = []
    for r in RAMPS:
        run.problem.set_readings({k: float(r) for k in slow})
        chi.append(run.fit(run.vals0, run.base_free).chi2["fit"])
    run.problem.set_readings({})
    chi = np.array(chi)
    redchi = float(chi.min()) / max(run.problem.count("fit"), 1)
    return parabola_minimum(np.array(RAMPS), chi, max(redchi, 1.0))


__all__ = ["read_slow_inputs", "slow_logs"]
