"""The logs as one simulation-error problem: channels, noise weights, parts, refits.

Every log is simulated on its own input with the shared kernel, from the state its first
samples measured (:mod:`pmdcid.simulate.initial`). A *channel* is one measured signal of one
log (current ``i`` of a voltage-driven log, speed ``omega``, angle ``theta``, a closed loop's
input ``u``), compared at a strided subset of its samples (at most ``max_samples`` per channel:
the kernel still runs at full rate; every sample when None), weighted by the signal's noise
level. The residual is ``(simulated - measured) / sigma`` per channel, non-finite values 0 (the
sign of every fit of pmdcid).

Which data are fitted and which held out is a per-log *plan* ('fit', 'held', 'split' or
'head'; see :func:`pmdcid.diagnose.folds.holdout_plan`): a log is fitted or held out whole, or
split in time (its first ``split`` fitted, the rest held out; 'head': the same split the other
way round, its head held out and its tail fitted: :mod:`pmdcid.diagnose.crosslog`). The
residual, the simulations it needs and its covariance are per *part*: 'fit', 'held' or
'all'. A simulation-error fit (:func:`pmdcid.fit.simfit.fit_simulation`) fits every sample of
the signals it names (plan 'fit'); diagnose judges its candidates on held-out data they were
not fitted on.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError, LogError
from pmdcid.fit.covariance import (
    CovarianceInfo,
    correlated_covariance,
    envelope_jacobian,
    information_inverse,
    standard_errors,
    white_covariance,
)
from pmdcid.fit.parameters import Parameters
from pmdcid.fit.results import Estimate, FitStats, fitted
from pmdcid.fit.solver import solve
from pmdcid.io.derive import derivative_noise_gain, noise_std, speed_cutoff, speed_from_position
from pmdcid.model.effects import bounds_of, unit_of
from pmdcid.model.spec import BASE_PARAMS
from pmdcid.simulate import SimResult, blocked_rotor, param_vector, simulate_values
from pmdcid.simulate.initial import initial_state, true_start
from pmdcid.simulate.layout import SIGMA0
from pmdcid.simulate.substeps import choose_substeps

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
PARTS = ("fit", "held", "all")


def refit_range(name: str, value: float) -> tuple[float, float]:
    """Where diagnose refits ``name`` from ``value``: its catalogue bounds, and a positive base
    parameter (R, L, J, bv...) within :data:`BASE_RANGE` of ``value``."""
    lo, hi = bounds_of(name)
    if name in BASE_PARAMS and value > 0 and BASE_PARAMS[name].lower > 0:
        lo, hi = max(lo, value / BASE_RANGE), min(hi, value * BASE_RANGE)
    return lo, hi


def noise_level(x: np.ndarray) -> float:
    """Robust white-noise std of a signal from its second difference (MAD), same unit as ``x``.

    For a quantised signal (encoder angle) the floor is quantum/sqrt(12).
    """
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if len(x) < 5:
        return 1.0
    s = noise_std(x)
    if s <= 0 or not math.isfinite(s):
        s = max(float(np.std(x)) * 1e-3, 1e-12)
    return s


def available_signals(log, signals: Sequence[str]) -> list[str]:
    """The ``signals`` a log can be compared on; ``u`` is its input column (a closed-loop
    simulation computes it: :mod:`pmdcid.simulate.closedloop`)."""
    return [s for s in signals if s == "u" or log.compares(s)]


@dataclass
class Channel:
    """One measured signal of one log at the compared samples ``rows``, every ``rows.step``-th
    sample of the log (a slice: no index array of the log's length is kept)."""

    log: int
    signal: str
    rows: slice
    meas: np.ndarray
    sigma: float
    fit: np.ndarray  # bool over the compared samples: fit part (True) or held-out (False)
    #: the speed was derived from the angle (filter + derivative, cut-off [Hz]): the simulated
    #: speed is derived the same way before the comparison
    derived_cutoff: float | None = None
    _parts: dict = field(default_factory=dict, repr=False)

    def part(self, part: str) -> tuple[np.ndarray, np.ndarray]:
        """(log sample indices, measured values) of ``part`` ('fit', 'held', 'all'), made once:
        every residual evaluation of a fit selects them (issue #16: Python time per call)."""
        got = self._parts.get(part)
        if got is None:
            if part == "all":
                got = (self.rows, self.meas)
            else:
                keep = self.fit if part == "fit" else ~self.fit
                idx = np.arange(self.rows.start, self.rows.stop, self.rows.step)[keep]
                got = (as_slice(idx), self.meas[keep])
            self._parts[part] = got
        return got


def compact(x: np.ndarray, rows: slice) -> np.ndarray:
    """``x`` at ``rows``: a view when the slice is contiguous (every sample compared), else a
    compact copy (a strided view would keep the whole array alive)."""
    return np.ascontiguousarray(x[rows])


def as_slice(idx: np.ndarray):
    """``idx`` (increasing sample indices) as a slice when evenly spaced (a channel's strided
    samples, or a prefix or suffix of them): selecting by a slice is a view, not a gather."""
    if len(idx) == 0:
        return slice(0, 0)
    step = int(idx[1] - idx[0]) if len(idx) > 1 else 1
    if step > 0 and np.array_equal(idx, np.arange(idx[0], idx[-1] + 1, step)):
        return slice(int(idx[0]), int(idx[-1]) + 1, step)
    return idx


@dataclass(frozen=True)
class Simulation:
    """How a problem simulates its logs: ``nsub`` internal steps per sample (None: the
    kernel's choice), ``capped`` at :data:`MAX_SUBSTEPS` (diagnose compares many candidates:
    speed before the last fraction of accuracy, which the written model's final refit
    restores), blocked-rotor logs held by stiction from rest (``hold_blocked``), each log from
    its measured first samples (``initial``) or from rest, and a ``simulator`` ``f(log, vals,
    x0)`` -> a result with ``.get(signal)`` replacing the open-loop simulation (the closed
    loop, :mod:`pmdcid.simulate.closedloop`)."""

    nsub: int | None = None
    capped: bool = False
    hold_blocked: bool = False
    initial: bool = True
    simulator: Callable | None = None


#: diagnose's simulations: capped internal steps, blocked rotors held
JUDGED = Simulation(capped=True, hold_blocked=True)


@dataclass
class FitOutcome:
    """A refit: values (all parameters), estimates of the free ones, chi-squares per part."""

    values: dict[str, float]
    estimates: dict[str, Estimate]
    stats: FitStats
    chi2: dict[str, float] = field(default_factory=dict)  # part -> chi-square
    n: dict[str, int] = field(default_factory=dict)


def simulate_capped(t: np.ndarray, u: np.ndarray, vals: dict[str, float], torque: bool,
                    x0=None, upto: int | None = None, *,
                    within: np.ndarray | None = None) -> SimResult:
    """:func:`pmdcid.simulate.simulate_values` from ``x0`` with at most :data:`MAX_SUBSTEPS`
    internal steps per sample. ``upto``: only the first samples (the same values as the whole
    simulation's: the kernel is causal); ``within``: the input inside each sample."""
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    p = param_vector(vals)
    nsub = min(choose_substeps(dt, p), LUGRE_MAX_SUBSTEPS if p[SIGMA0] > 0 else MAX_SUBSTEPS)
    if upto is not None and upto < len(t):
        if within is not None:
            within = within[:upto * (len(within) // len(u))]
        t, u = t[:upto], u[:upto]
    return simulate_values(t, u, vals, torque, nsub, x0, dt=dt, within=within)


class Problem:
    """Simulate and compare a parameter set on all logs; refit chosen parameters.

    ``signals``: the signals compared, in this order, on every log that has them, weighted by
    ``sigma[k][signal]`` where given (else their noise level); None is diagnose's choice: every
    signal a log measures by its own sensor (the angle dropped beside a speed), a speed derived
    from the angle compared as the simulated angle's speed derived the same way, on logs of at
    least :data:`MIN_SAMPLES` samples."""

    def __init__(self, logs: Sequence, split: float = 0.6, max_samples: int | None = 20000,
                 plan: Sequence[str] | None = None, *, signals: Sequence[str] | None = None,
                 sigma: Sequence[dict[str, float]] | None = None,
                 simulation: Simulation = JUDGED):
        self.logs = list(logs)
        self.split = split
        self.plan = list(plan) if plan is not None else ["split"] * len(self.logs)
        self.simulation = simulation
        given = list(sigma or []) + [{}] * (len(self.logs) - len(sigma or []))
        self.channels: list[Channel] = []
        for k, log in enumerate(self.logs):
            stride = 1 if max_samples is None else max(1, int(math.ceil(log.n / max_samples)))
            rows = slice(0, log.n, stride)
            fit = compact(self.fit_mask(k), rows)
            if signals is None:
                self.channels += _judged_channels(k, log, rows, fit)
            else:
                self.channels += [_channel(k, log, s, rows, fit, given[k])
                                  for s in available_signals(log, signals)]
        borrow_noise(self.channels, given)
        self._check(signals)
        self.blocked = [log.blocked for log in self.logs]
        self._needs: dict[str, list[int]] = {}
        self._blocks: dict[str, list[tuple[Channel, int, int]]] = {}
        #: log -> how its input varied between samples (``ramp``;
        #: :mod:`pmdcid.diagnose.slow_inputs`)
        self.readings: dict[int, float] = {}
        # each log from the state its first samples measured (a log that starts turning is
        # never credited to an effect); a blocked rotor held from rest
        self.x0 = [np.zeros(3) if not simulation.initial or (simulation.hold_blocked and b)
                   else initial_state(log, given[k].get("omega"))
                   for k, (log, b) in enumerate(zip(self.logs, self.blocked, strict=True))]

    def _check(self, signals) -> None:
        if not self.channels and signals is not None:
            raise FitError(f"no log carries any of the signals {', '.join(signals)} to fit")
        names = ", ".join(lg.path for lg in self.logs)
        if not self.channels:
            raise LogError("no log carries current, speed or angle to compare the model with",
                           names)
        longest = max(log.n for log in self.logs)
        if signals is None and longest < MIN_SAMPLES:
            raise LogError(f"too short to judge an effect: {longest} samples at most "
                           f"(diagnose needs a log of at least {MIN_SAMPLES})", names)

    def set_readings(self, readings: dict[int, float]) -> None:
        """Read the input of each log ``k`` in ``readings`` at ramp ``readings[k]`` between
        samples (0 held, 1 straight to the next sample); the other logs held."""
        self.readings = dict(readings)

    def needs(self, part: str) -> list[int]:
        """Per log, the samples to simulate for the residual of ``part`` (:meth:`_needed`)."""
        got = self._needs.get(part)
        if got is None:
            got = self._needs[part] = [self._needed(k, part) for k in range(len(self.logs))]
        return got

    def _needed(self, k: int, part: str) -> int:
        """Samples of log ``k`` to simulate for the residual of ``part``: every sample for
        'all' (and 'held', a suffix), none when the part has no sample of the log (a log held
        out whole has no fit part), and for the fit part of a log split in time only up to its
        last compared sample: the kernel, its input and its sensors are causal. All of them
        when a channel derives the speed by a zero-phase filter (it looks ahead)."""
        n = self.logs[k].n
        if part == "all":
            return n
        chans = [ch for ch in self.channels if ch.log == k]
        last = -1
        for ch in chans:
            picked = np.arange(n)[ch.part(part)[0]]
            if len(picked):
                last = max(last, int(picked[-1]))
        if last >= 0 and part == "held":
            return n
        if last < 0:
            return 0
        return n if any(ch.derived_cutoff is not None for ch in chans) else last + 1

    def fit_mask(self, k: int) -> np.ndarray:
        """Samples of log ``k`` (full rate) that are fitted: all, none, its first part
        ('split') or the rest ('head': its first part held out)."""
        log = self.logs[k]
        plan = self.plan[k]
        if plan in ("fit", "held"):
            return np.full(log.n, plan == "fit")
        head = log.t < log.t[0] + self.split * log.duration
        return ~head if plan == "head" else head

    @property
    def held_logs(self) -> list[int]:
        """Logs held out whole."""
        return [k for k, p in enumerate(self.plan) if p == "held"]

    def simulate(self, vals: dict[str, float], k: int, upto: int | None = None, *,
                 x0=None, out=None) -> SimResult:
        """Log ``k`` simulated with ``vals`` (its first ``upto`` samples when given), from
        ``x0`` (default: its measured start, :func:`~pmdcid.simulate.initial.true_start`);
        ``out``: the kernel's state buffer to reuse (uncapped simulations)."""
        log = self.logs[k]
        sim = self.simulation
        if sim.hold_blocked and self.blocked[k]:
            vals = blocked_rotor(vals)
        if k in self.readings:
            vals = {**vals, "ramp": self.readings[k]}
        x0 = true_start(self.x0[k], vals) if x0 is None else x0
        if sim.simulator is not None:
            return sim.simulator(log, vals, x0)
        within = log.input_within()
        if sim.capped:
            return simulate_capped(log.t, log.u, vals, log.drive == "tau", x0, upto,
                                   within=within)
        return simulate_values(log.t, log.u, vals, log.drive == "tau", sim.nsub, x0, out,
                               within=within)

    def simulate_all(self, vals: dict[str, float], part: str = "all") -> list:
        """Every log simulated with ``vals``; for ``part`` 'fit' or 'held' only as far as that
        part's residual needs (:meth:`_needed`; None for a log it does not use): on the demo
        logs the fit part's simulations take 60 % of the steps. Pass the same ``part`` to
        :meth:`weighted`."""
        return [self.simulate(vals, k, m) if m else None
                for k, m in enumerate(self.needs(part))]

    def simulated(self, sims: list[SimResult], ch: Channel, idx=None) -> np.ndarray:
        """The simulated counterpart of channel ``ch`` at its samples (or at the samples ``idx``
        of the log): a derived speed compares with the simulated angle's speed derived by the
        same zero-phase filter and derivative (an unfiltered simulated speed would differ at
        every stick-slip edge)."""
        sim = sims[ch.log]
        idx = ch.rows if idx is None else idx
        if ch.derived_cutoff is not None:
            log = self.logs[ch.log]
            return speed_from_position(sim.theta, log.dt, ch.derived_cutoff)[idx]
        return sim.get(ch.signal)[idx]

    def residual(self, sims: list[SimResult], ch: Channel) -> np.ndarray:
        """Simulated - measured at channel ``ch``'s samples, in the signal's unit."""
        return self.simulated(sims, ch) - ch.meas

    def blocks(self, part: str) -> list[tuple[Channel, int, int]]:
        """The residual's blocks for ``part``: (channel, first row, end row) of each channel
        with samples in it, in the residual's order."""
        got = self._blocks.get(part)
        if got is None:
            got, row = [], 0
            for ch in self.channels:
                n = len(ch.part(part)[1])
                if n:
                    got.append((ch, row, row + n))
                    row += n
            self._blocks[part] = got
        return got

    def segments(self, part: str) -> list[tuple[int, int, int]]:
        """(log index, first row, end row) of each block of ``part`` (the covariance's)."""
        return [(ch.log, a, b) for ch, a, b in self.blocks(part)]

    def rows(self, part: str) -> int:
        blocks = self.blocks(part)
        return blocks[-1][2] if blocks else 0

    def weighted(self, sims: list[SimResult], part: str = "fit", out=None,
                 whiten=None) -> np.ndarray:
        """(simulated - measured) / sigma over the channels' samples of ``part`` ('fit', 'held'
        or 'all'), non-finite values 0; each block filtered by its ``whiten[j]`` when given
        (an AR noise model, :func:`pmdcid.fit.simfit.ar_whitener`). Into the first rows of
        ``out`` when given."""
        out = np.empty(self.rows(part)) if out is None else out
        for j, (ch, a, b) in enumerate(self.blocks(part)):
            idx, meas = ch.part(part)
            r = out[a:b]
            np.subtract(self.simulated(sims, ch, idx), meas, out=r)
            r /= ch.sigma
            r[~np.isfinite(r)] = 0.0
            if whiten is not None and whiten[j] is not None:
                # the FIR filter A(q): numpy, not scipy.signal (1 s import)
                r[:] = np.convolve(r, whiten[j])[: len(r)]
        return out

    def chi2(self, vals: dict[str, float]) -> dict[str, float]:
        sims = self.simulate_all(vals)
        return {p: float(np.sum(self.weighted(sims, p) ** 2)) for p in PARTS}

    def cost(self, vals: dict[str, float], part: str) -> float:
        """``chi2(vals)[part]`` (the same number), simulating only what ``part`` needs."""
        return float(np.sum(self.weighted(self.simulate_all(vals, part), part) ** 2))

    def count(self, part: str) -> int:
        return sum(int(ch.fit.sum()) if part == "fit" else int((~ch.fit).sum())
                   if part == "held" else len(ch.meas) for ch in self.channels)

    def measures(self, signal: str) -> bool:
        """Some log measures ``signal`` by its own sensor (not derived from another signal)."""
        return any(log.has(signal) and signal not in log.derived for log in self.logs)

    def has_signal(self, signal: str, moving: bool | None = None) -> bool:
        return any(ch.signal == signal and (moving is None or moving != self.blocked[ch.log])
                   for ch in self.channels)

    def start(self, params) -> np.ndarray:
        """``params.start()``, its refusal (no room, no finite start) naming these logs: the
        range that left no room came from them."""
        try:
            return params.start()
        except FitError as exc:
            if exc.path is not None:
                raise
            paths = ", ".join(dict.fromkeys(str(lg.path) for lg in self.logs if lg.path))
            raise FitError(str(exc), paths or None) from None

    def refit_parameters(self, vals: dict[str, float], free: Sequence[str],
                         typical_scale: dict[str, float] | None = None,
                         limits: dict[str, tuple[float, float]] | None = None) -> Parameters:
        """diagnose's refit of ``free`` from ``vals``: catalogue bounds tightened by ``limits``,
        positive base parameters within :data:`BASE_RANGE` of their start, wider steps for the
        switching parameters; ``typical_scale``: the size of parameters that start at 0."""
        params = Parameters.of(free, vals, steps={n: SWITCH_STEP for n in SWITCHING},
                               typical=typical_scale)
        for n, p in params.items():
            if limits and n in limits:
                params.tighten(n, *limits[n])
            params.tighten(n, *refit_range(n, p.value))
        return params

    def fit(self, vals: dict[str, float], free: Sequence[str], part: str = "fit",
            max_nfev: int = 40, typical_scale: dict[str, float] | None = None,
            limits: dict[str, tuple[float, float]] | None = None) -> FitOutcome:
        """Least squares (:func:`~pmdcid.fit.solver.solve`) of ``free`` by simulation error on
        ``part``, from ``vals`` (:meth:`refit_parameters`); a name given twice is fitted once."""
        free = list(dict.fromkeys(free))
        if not free:
            c = self.chi2(vals)
            stats = FitStats(self.count(part), 0, c[part], 1)
            return FitOutcome(dict(vals), {}, stats, c, {p: self.count(p) for p in c})
        params = self.refit_parameters(vals, free, typical_scale, limits)
        x0 = self.start(params)
        scale = params.scales(x0)
        lo, hi = params.bounds()

        def with_x(z):
            v = dict(vals)
            v.update(zip(free, z * scale, strict=True))
            return v

        def resid(z):
            return self.weighted(self.simulate_all(with_x(z), part), part)

        sol = solve(resid, x0 / scale, lo / scale, hi / scale, scale=scale,
                    diff_step=params.steps(), max_nfev=max_nfev, what="diagnose refit",
                    parallel=True)
        out = with_x(sol.z)
        stats = FitStats(len(sol.fun), len(free), float(np.sum(sol.fun**2)), sol.nfev,
                         sol.success, sol.message)
        try:
            se = standard_errors(white_covariance(sol.jac, sol.fun))
        except np.linalg.LinAlgError:
            se = np.full(len(free), math.nan)
        est = {nm: fitted(nm, out[nm], e, unit_of(nm))
               for nm, e in zip(free, se, strict=True)}
        c = self.chi2(out)
        return FitOutcome(out, est, stats, c, {p: self.count(p) for p in c})

    def correlated_stderr(self, vals: dict[str, float], free: Sequence[str],
                          rel: float = 1e-2) -> tuple[dict[str, float], CovarianceInfo | None]:
        """Standard errors of ``free`` at ``vals`` on all the data, allowing for a residual
        correlated in time (block sandwich, :mod:`pmdcid.fit.covariance`): the refits'
        white-residual errors count every sample as independent evidence. Central differences
        with relative step ``rel`` (2 simulations per parameter)."""
        se, info, _ = self.envelope_errors(vals, free, rel)
        return se, info

    def envelope_errors(self, vals: dict[str, float], free: Sequence[str],
                        rel: float = 1e-2) -> tuple[dict[str, float], CovarianceInfo | None,
                                                    np.ndarray | None]:
        """:meth:`correlated_stderr`'s standard errors and info, and the envelope Jacobian's
        inverse curvature ``(J'J)^-1`` over the names of ``free`` found in ``vals`` (in that
        order; None when it cannot be inverted): the direction a profile follows
        (:func:`pmdcid.identify.dead_zone.profile_line`)."""
        free = [n for n in free if n in vals]
        if not free:
            return {}, None, None
        params = Parameters.of(free, vals)
        x0 = np.array([vals[n] for n in free], float)
        scale = params.scales(x0)

        def resid(z):
            v = dict(vals)
            v.update(zip(free, z * scale, strict=True))
            return self.weighted(self.simulate_all(v), "all")

        z0 = x0 / scale
        f0 = resid(z0)
        lo, hi = params.bounds()
        jm = envelope_jacobian(resid, z0, f0, lo / scale, hi / scale, rel) / scale[None, :]
        try:
            curv = information_inverse(jm.T @ jm)
            cov, info = correlated_covariance(jm, f0, self.segments("all"))
        except np.linalg.LinAlgError:
            return {}, None, None
        se = standard_errors(cov)
        return dict(zip(free, (float(e) for e in se), strict=True)), info, curv


def _varies(x: np.ndarray) -> bool:
    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    return x.size > 0 and float(np.ptp(x)) > 0


def _floors(pairs) -> dict[str, float]:
    """signal -> the smallest noise level among the ``(signal, varies, sigma)`` that vary."""
    out: dict[str, float] = {}
    for sig, varies, sigma in pairs:
        if varies:
            out[sig] = min(out.get(sig, math.inf), sigma)
    return out


def borrow_noise(channels: Sequence[Channel], given: Sequence[dict[str, float]]) -> None:
    """A signal logged exactly constant (a speed of exact zeros: no noise to measure, and
    :func:`noise_level`'s floor would weigh it 1e9 times the others) takes the smallest noise
    level the same signal shows in another log, unless its sigma was given."""
    flags = [_varies(ch.meas) for ch in channels]
    floor = _floors((ch.signal, f, ch.sigma) for ch, f in zip(channels, flags, strict=True))
    for ch, f in zip(channels, flags, strict=True):
        if not f and ch.signal in floor and ch.signal not in given[ch.log]:
            ch.sigma = max(ch.sigma, floor[ch.signal])


def noise_levels(logs: Sequence, signals: Sequence[str]) -> list[dict[str, float]]:
    """Each log's :func:`noise_level` per signal it has, a signal logged exactly constant
    taking the smallest level the same signal shows in another log (:func:`borrow_noise`)."""
    out = [{s: noise_level(lg[s]) for s in signals if lg.has(s)} for lg in logs]
    flags = [{s: _varies(lg[s]) for s in sig} for lg, sig in zip(logs, out, strict=True)]
    floor = _floors((s, f[s], sig[s]) for sig, f in zip(out, flags, strict=True) for s in sig)
    for sig, f in zip(out, flags, strict=True):
        for s in sig:
            if not f[s] and s in floor:
                sig[s] = max(sig[s], floor[s])
    return out


def _channel(k: int, log, s: str, rows, fit, given: dict[str, float]) -> Channel:
    """Signal ``s`` of log ``k`` weighted by ``given[s]``, else by its noise level; a speed
    derived from the angle compares with the simulated angle's speed derived the same way
    (:func:`_derived_cutoff`)."""
    x = np.asarray(log.u if s == "u" else log[s], float)
    fc = _derived_cutoff(log, s)
    sigma = given.get(s)
    if sigma is None:
        sigma = noise_level(x) if fc is None else _derived_sigma(log, x, fc)
    return Channel(k, s, rows, compact(x, rows), float(sigma), fit, fc)


def _derived_cutoff(log, s: str) -> float | None:
    """The cut-off [Hz] of the filter that derived ``s`` from the log's angle, None when ``s``
    is measured by its own sensor."""
    return speed_cutoff(log) if s == "omega" else None


def _derived_sigma(log, x: np.ndarray, fc: float) -> float:
    """Noise std of a speed ``x`` derived from the log's angle with cut-off ``fc``: filtered
    noise is smooth, so its second differences say nothing; the angle's own noise (an
    encoder's quantisation) through the filter and derivative does."""
    return max(noise_level(x), derivative_noise_gain(log.dt, fc, 1)
               * noise_std(np.asarray(log["theta"], float)))


def _judged_channels(k: int, log, rows, fit) -> list[Channel]:
    """diagnose's channels of log ``k``: every signal measured by its own sensor."""
    have = log.compared_signals()
    measured = [s for s in have if s not in log.derived] or have
    if "omega" in have and "theta" in measured:
        # the angle integrates every force error: weighted by an encoder's tiny noise, the
        # drift of a model still lacking an effect would swamp the cost (see
        # docs/identification.md, fit-nonlinear's signals)
        measured.remove("theta")
        if "omega" not in measured:
            measured.append("omega")
    out = []
    for s in measured:
        x = np.asarray(log[s], float)
        fc = _derived_cutoff(log, s)
        sigma = noise_level(x) if fc is None else _derived_sigma(log, x, fc)
        out.append(Channel(k, s, rows, compact(x, rows), sigma, fit, fc))
    return out


__all__ = ["JUDGED", "Channel", "FitOutcome", "Problem", "Simulation",
           "available_signals", "borrow_noise", "noise_level", "noise_levels", "refit_range"]
