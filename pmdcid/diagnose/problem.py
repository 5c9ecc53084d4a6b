"""The logs as one simulation-error problem: channels, noise weights, time split, refits.

Every log is simulated from rest on its own input with the shared kernel (blocked-rotor logs with
the rotor held). A *channel* is one measured signal of one log (current ``i`` of a voltage-driven
log, speed ``omega``, angle ``theta``), compared at a strided subset of its samples (at most
``max_samples`` per channel: the kernel still runs at full rate), weighted by the signal's noise
level. Which data are fitted and which held out is a per-log *plan*
(:func:`pmdcid.diagnose.folds.holdout_plan`): a repeat of a protocol is held out or fitted whole,
a log without a repeat is split in time (its first ``split`` fitted, the rest held out). Held-out
data are never used to fit: on them diagnose checks that an effect's gain is real.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError, LogError
from pmdcid.identify.covariance import CovarianceInfo, block_covariance
from pmdcid.identify.results import Estimate, FitStats
from pmdcid.identify.simfit import envelope_jacobian, noise_level
from pmdcid.identify.solver import scale_of, solve, white_covariance
from pmdcid.io.derive import derivative_noise_gain, log_cutoff, noise_std, speed_from_position
from pmdcid.model.effects import bounds_of, unit_of
from pmdcid.model.spec import BASE_PARAMS
from pmdcid.simulate import SimResult, blocked_rotor, param_vector, simulate_values
from pmdcid.simulate.initial import initial_state, true_start
from pmdcid.simulate.layout import SIGMA0
from pmdcid.simulate.substeps import choose_substeps


@dataclass
class Channel:
    """One measured signal of one log at the compared samples ``idx``."""

    log: int
    signal: str
    idx: np.ndarray
    meas: np.ndarray
    sigma: float
    fit: np.ndarray  # bool over idx: fit part (True) or held-out (False)
    #: the speed was derived from the angle (filter + derivative, cut-off [Hz]): the simulated
    #: speed is derived the same way before the comparison
    derived_cutoff: float | None = None
    _parts: dict = field(default_factory=dict, repr=False)

    def part(self, part: str) -> tuple[np.ndarray, np.ndarray]:
        """(log sample indices, measured values) of ``part`` ('fit', 'held', 'all'), made once:
        every residual evaluation of a fit selects them (issue #16: Python time per call)."""
        got = self._parts.get(part)
        if got is None:
            keep = (slice(None) if part == "all" else self.fit if part == "fit"
                    else ~self.fit)
            got = self._parts[part] = (as_slice(self.idx[keep]), self.meas[keep])
        return got


def as_slice(idx: np.ndarray):
    """``idx`` (increasing sample indices) as a slice when evenly spaced (a channel's strided
    samples, or a prefix or suffix of them): selecting by a slice is a view, not a gather."""
    if len(idx) == 0:
        return slice(0, 0)
    step = int(idx[1] - idx[0]) if len(idx) > 1 else 1
    if step > 0 and np.array_equal(idx, np.arange(idx[0], idx[-1] + 1, step)):
        return slice(int(idx[0]), int(idx[-1]) + 1, step)
    return idx


@dataclass
class FitOutcome:
    """A refit: values (all parameters), estimates of the free ones, chi-squares per part."""

    values: dict[str, float]
    estimates: dict[str, Estimate]
    stats: FitStats
    chi2: dict[str, float] = field(default_factory=dict)  # part -> chi-square
    n: dict[str, int] = field(default_factory=dict)


#: fewest samples of the longest log: fewer cannot tell an effect from the noise
MIN_SAMPLES = 50
#: cap on internal steps per sample (a refit wandering to a tiny J/bv must not stall)
MAX_SUBSTEPS = 16
#: the cap with LuGre on: its bristle spring is held over a step, stable only for steps below
#: :func:`pmdcid.simulate.substeps.lugre_step`
LUGRE_MAX_SUBSTEPS = 256
#: positive base parameters are refitted within this factor of their starting value
BASE_RANGE = 30.0
#: parameters that move stick-slip and dead-zone events by whole internal steps: their
#: finite-difference step must span several (as in fit-nonlinear)
SWITCHING = ("bc", "dz", "fs", "tau0")
SWITCH_STEP = 1e-2


def simulate_capped(t: np.ndarray, u: np.ndarray, vals: dict[str, float], torque: bool,
                    x0=None, upto: int | None = None) -> SimResult:
    """:func:`pmdcid.simulate.simulate_values` from ``x0`` with at most :data:`MAX_SUBSTEPS`
    internal steps per sample (diagnose compares many candidates: speed before the last
    fraction of accuracy, which the written model's final refit restores). ``upto``: only the
    first samples (the same values as the whole simulation's: the kernel is causal)."""
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    p = param_vector(vals)
    nsub = min(choose_substeps(dt, p), LUGRE_MAX_SUBSTEPS if p[SIGMA0] > 0 else MAX_SUBSTEPS)
    if upto is not None and upto < len(t):
        t, u = t[:upto], u[:upto]
    return simulate_values(t, u, vals, torque, nsub, x0, dt=dt)


class Problem:
    """Simulate and compare a parameter set on all logs; refit chosen parameters."""

    def __init__(self, logs: Sequence, split: float = 0.6, max_samples: int = 20000,
                 plan: Sequence[str] | None = None):
        self.logs = list(logs)
        self.split = split
        self.plan = list(plan) if plan is not None else ["split"] * len(self.logs)
        self.channels: list[Channel] = []
        for k, log in enumerate(self.logs):
            have = log.compared_signals()
            measured = [s for s in have if s not in log.derived] or have
            if "omega" in have and "theta" in measured:
                # the angle integrates every force error: weighted by an encoder's tiny noise,
                # the drift of a model still lacking an effect would swamp the cost (see
                # docs/identification.md, fit-nonlinear's signals)
                measured.remove("theta")
                if "omega" not in measured:
                    measured.append("omega")
            stride = max(1, int(math.ceil(log.n / max_samples)))
            idx = np.arange(0, log.n, stride)
            fit = self.fit_mask(k)[idx]
            for s in measured:
                x = np.asarray(log[s], float)
                fc = log_cutoff(log) if s == "omega" and s in log.derived else None
                sigma = noise_level(x)
                if fc is not None and log.has("theta"):
                    # filtered noise is smooth: its second differences say nothing. The angle's
                    # noise (encoder quantisation) through the filter and derivative does.
                    sigma = max(sigma, derivative_noise_gain(log.dt, fc, 1)
                                * noise_std(np.asarray(log["theta"], float)))
                self.channels.append(Channel(k, s, idx, x[idx], sigma, fit, fc))
        names = ", ".join(lg.path for lg in self.logs)
        if not self.channels:
            raise LogError("no log carries current, speed or angle to compare the model with",
                           names)
        if max(log.n for log in self.logs) < MIN_SAMPLES:
            raise LogError(f"too short to judge an effect: {max(log.n for log in self.logs)} "
                           f"samples at most (diagnose needs a log of at least {MIN_SAMPLES})",
                           names)
        self.blocked = [log.blocked for log in self.logs]
        self.needs = {part: [self._needed(k, part) for k in range(len(self.logs))]
                      for part in ("fit", "held", "all")}
        #: log -> how its input varied between samples (``ramp``; :mod:`pmdcid.diagnose.hold`)
        self.readings: dict[int, float] = {}
        # each log from the state its first samples measured (a log that starts turning is
        # never credited to an effect); a blocked rotor from rest
        self.x0 = [np.zeros(3) if b else initial_state(log)
                   for log, b in zip(self.logs, self.blocked, strict=True)]

    def set_readings(self, readings: dict[int, float]) -> None:
        """Read the input of each log ``k`` in ``readings`` at ramp ``readings[k]`` between
        samples (0 held, 1 straight to the next sample); the other logs held."""
        self.readings = dict(readings)

    def _needed(self, k: int, part: str) -> int:
        """Samples of log ``k`` to simulate for the residual of ``part``: every sample for
        'all' (and 'held', a suffix), none when the part has no sample of the log (a log held
        out whole has no fit part), and for the fit part of a log split in time only up to its
        last compared sample: the kernel, its input and its sensors are causal. All of them
        when a channel derives the speed by a zero-phase filter (it looks ahead)."""
        n = self.logs[k].n
        chans = [ch for ch in self.channels if ch.log == k]
        last = -1
        for ch in chans:
            picked = np.arange(n)[ch.part(part)[0]]
            if len(picked):
                last = max(last, int(picked[-1]))
        if part == "all" or (last >= 0 and part == "held"):
            return n
        if last < 0:
            return 0
        return n if any(ch.derived_cutoff is not None for ch in chans) else last + 1

    def fit_mask(self, k: int) -> np.ndarray:
        """Samples of log ``k`` (full rate) that are fitted: all, none, or its first part."""
        log = self.logs[k]
        plan = self.plan[k]
        if plan in ("fit", "held"):
            return np.full(log.n, plan == "fit")
        return log.t < log.t[0] + self.split * log.duration

    @property
    def held_logs(self) -> list[int]:
        """Logs held out whole."""
        return [k for k, p in enumerate(self.plan) if p == "held"]

    def simulate(self, vals: dict[str, float], k: int, upto: int | None = None) -> SimResult:
        """Log ``k`` simulated with ``vals`` (its first ``upto`` samples when given)."""
        log = self.logs[k]
        if self.blocked[k]:
            vals = blocked_rotor(vals)
        if k in self.readings:
            vals = {**vals, "ramp": self.readings[k]}
        return simulate_capped(log.t, log.u, vals, log.drive == "tau",
                               true_start(self.x0[k], vals), upto)

    def simulate_all(self, vals: dict[str, float], part: str = "all") -> list:
        """Every log simulated with ``vals``; for ``part`` 'fit' or 'held' only as far as that
        part's residual needs (:meth:`_needed`; None for a log it does not use): on the demo
        logs the fit part's simulations take 60 % of the steps. Pass the same ``part`` to
        :meth:`weighted`."""
        return [self.simulate(vals, k, m) if m else None
                for k, m in enumerate(self.needs[part])]

    def simulated(self, sims: list[SimResult], ch: Channel, idx=None) -> np.ndarray:
        """The simulated counterpart of channel ``ch`` at its samples (or at the samples ``idx``
        of the log): a derived speed compares with the simulated angle's speed derived by the
        same zero-phase filter and derivative (an unfiltered simulated speed would differ at
        every stick-slip edge)."""
        sim = sims[ch.log]
        idx = ch.idx if idx is None else idx
        if ch.derived_cutoff is not None:
            log = self.logs[ch.log]
            return speed_from_position(sim.theta, log.dt, ch.derived_cutoff)[idx]
        return sim.get(ch.signal)[idx]

    def residual(self, sims: list[SimResult], ch: Channel) -> np.ndarray:
        """Simulated - measured at channel ``ch``'s samples (the sign of every fit of pmdcid,
        :mod:`pmdcid.identify.solver`), in the signal's unit."""
        return self.simulated(sims, ch) - ch.meas

    def weighted(self, sims: list[SimResult], part: str = "fit") -> np.ndarray:
        """(simulated - measured) / sigma over the channels' samples of ``part``.

        ``part`` is 'fit', 'held' or 'all'.
        """
        out = []
        for ch in self.channels:
            idx, meas = ch.part(part)
            if not len(meas):
                continue
            sim = self.simulated(sims, ch, idx)
            r = np.subtract(sim, meas, out=sim if sim.base is None else None)
            r /= ch.sigma
            r[~np.isfinite(r)] = 0.0
            out.append(r)
        return np.concatenate(out)

    def chi2(self, vals: dict[str, float]) -> dict[str, float]:
        sims = self.simulate_all(vals)
        return {p: float(np.sum(self.weighted(sims, p) ** 2)) for p in ("fit", "held", "all")}

    def cost(self, vals: dict[str, float], part: str) -> float:
        """``chi2(vals)[part]`` (the same number), simulating only what ``part`` needs."""
        return float(np.sum(self.weighted(self.simulate_all(vals, part), part) ** 2))

    def count(self, part: str) -> int:
        return sum(int(ch.fit.sum()) if part == "fit" else int((~ch.fit).sum())
                   if part == "held" else len(ch.idx) for ch in self.channels)

    def measures(self, signal: str) -> bool:
        """Some log measures ``signal`` by its own sensor (not derived from another signal)."""
        return any(log.has(signal) and signal not in log.derived for log in self.logs)

    def has_signal(self, signal: str, moving: bool | None = None) -> bool:
        return any(ch.signal == signal and (moving is None or moving != self.blocked[ch.log])
                   for ch in self.channels)

    def fit(self, vals: dict[str, float], free: Sequence[str], part: str = "fit",
            max_nfev: int = 40, typical_scale: dict[str, float] | None = None,
            limits: dict[str, tuple[float, float]] | None = None) -> FitOutcome:
        """Least squares (scipy TRF) of ``free`` by simulation error on ``part``, from ``vals``.

        ``typical_scale`` gives the size of parameters whose start is 0 (default 1 in SI);
        ``limits`` tightens the catalogue bounds of some parameters (name -> (lower, upper)).
        """
        free = list(free)
        if not free:
            c = self.chi2(vals)
            stats = FitStats(self.count(part), 0, c[part], 1)
            return FitOutcome(dict(vals), {}, stats, c, {p: self.count(p) for p in c})
        x0 = np.array([vals[n] for n in free], float)
        lo = np.array([bounds_of(n)[0] for n in free])
        hi = np.array([bounds_of(n)[1] for n in free])
        for j, n in enumerate(free):
            if limits and n in limits:
                lo[j], hi[j] = max(lo[j], limits[n][0]), min(hi[j], limits[n][1])
            if n in BASE_PARAMS and x0[j] > 0 and BASE_PARAMS[n].lower > 0:
                lo[j] = max(lo[j], x0[j] / BASE_RANGE)
                hi[j] = min(hi[j], x0[j] * BASE_RANGE)
        x0 = np.clip(x0, lo, hi)
        if not np.all(np.isfinite(x0)):
            bad = [n for n, v in zip(free, x0, strict=True) if not math.isfinite(v)]
            raise FitError(f"no finite starting value for {', '.join(bad)}")
        typical = np.array([(typical_scale or {}).get(n, 1.0) for n in free])
        scale = scale_of(x0, typical)

        def with_x(z):
            v = dict(vals)
            v.update(zip(free, z * scale, strict=True))
            return v

        def resid(z):
            return self.weighted(self.simulate_all(with_x(z), part), part)

        steps = np.array([SWITCH_STEP if n in SWITCHING else 1e-3 for n in free])
        sol = solve(resid, x0 / scale, lo / scale, hi / scale, scale=scale, diff_step=steps,
                    max_nfev=max_nfev, what="diagnose refit", parallel=True)
        out = with_x(sol.z)
        stats = FitStats(len(sol.fun), len(free), float(np.sum(sol.fun**2)), sol.nfev,
                         sol.success, sol.message)
        try:
            se = np.sqrt(np.clip(np.diag(white_covariance(sol.jac, sol.fun)), 0, None))
        except np.linalg.LinAlgError:
            se = np.full(len(free), math.nan)
        est = {nm: Estimate(nm, float(out[nm]), float(e), unit_of(nm))
               for nm, e in zip(free, se, strict=True)}
        c = self.chi2(out)
        return FitOutcome(out, est, stats, c, {p: self.count(p) for p in c})

    def correlated_stderr(self, vals: dict[str, float], free: Sequence[str],
                          rel: float = 1e-2) -> tuple[dict[str, float], CovarianceInfo | None]:
        """Standard errors of ``free`` at ``vals`` on all the data, allowing for a residual
        correlated in time (block sandwich, :mod:`pmdcid.identify.covariance`): the refits'
        white-residual errors count every sample as independent evidence. Central differences
        with relative step ``rel`` (2 simulations per parameter)."""
        free = [n for n in free if n in vals]
        if not free:
            return {}, None
        x0 = np.array([vals[n] for n in free], float)
        scale = np.where(np.abs(x0) > 0, np.abs(x0), 1.0)

        def resid(z):
            v = dict(vals)
            v.update(zip(free, z * scale, strict=True))
            return self.weighted(self.simulate_all(v), "all")

        z0 = x0 / scale
        f0 = resid(z0)
        lo = np.array([bounds_of(n)[0] for n in free]) / scale
        hi = np.array([bounds_of(n)[1] for n in free]) / scale
        jm = envelope_jacobian(resid, z0, f0, lo, hi, rel) / scale[None, :]
        segments, row = [], 0
        for ch in self.channels:
            segments.append(((ch.log, len(ch.idx)), row, row + len(ch.idx)))
            row += len(ch.idx)
        n = len(f0)
        try:
            white = np.linalg.pinv(jm.T @ jm) * float(f0 @ f0) / max(n - len(free), 1)
            cov, info = block_covariance(jm, f0, segments, white)
        except np.linalg.LinAlgError:
            return {}, None
        se = np.sqrt(np.clip(np.diag(cov), 0, None))
        return dict(zip(free, (float(e) for e in se), strict=True)), info


__all__ = ["Channel", "FitOutcome", "Problem"]
