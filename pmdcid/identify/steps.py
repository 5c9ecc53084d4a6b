"""Step responses: finding the step, Strejc's method, and least-squares step-response fits.

Small pure functions shared by fit-electrical and fit-mechanical. Time in s; the response ``y``
in its own unit (A or rad/s); the input ``u`` in V.

The step is found in the input column alone (no position given by the user), against the
input's own noise (:func:`find_steps`: a commanded input sample to sample, a measured, noisy one
between means of up to :data:`MAX_SCALE` samples); the levels before and after are the plateaus'
means, the onset is the first sample where the input crosses half-way. The kernel's (and a
DAC's) zero-order hold makes the new level act from that sample's instant on, so the response
model starts there; a dead time ``d`` >= 0 absorbs sensor or drive latency.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.covariance import block_covariance, standard_errors, white_covariance
from pmdcid.fit.solver import scale_of, solve
from pmdcid.io.derive import mad_std

#: Strejc's table: Tu/Tn of the tangent at the inflection point for n equal lags, n = 1..6
STREJC_TU_TN = (0.0, 0.104, 0.218, 0.319, 0.410, 0.493)


@dataclass
class StepInfo:
    """A step found in an input: sample index and time [s] of the onset, levels before/after."""

    onset: int
    t0: float
    before: float
    after: float
    #: end of the plateau (exclusive sample index; None: the log's end) and the first sample of
    #: the interval before the step (its previous plateau)
    end: int | None = None
    prev_start: int = 0
    #: standard error of the level before [unit of the input] (a noisy measured input)
    before_se: float = 0.0

    @property
    def amplitude(self) -> float:
        return self.after - self.before


def find_step(t: np.ndarray, u: np.ndarray, path: str | None = None) -> StepInfo:
    """Locate the one step in input ``u`` (e.g. V): onset, level before and after.

    Raises :class:`FitError` when the input holds no clear step (constant, or the change is not
    much larger than its scatter).
    """
    u = np.asarray(u, float)
    n = len(u)
    if n < MIN_PLATEAU_SAMPLES:
        raise FitError(f"{path}: too short ({n} samples) to hold a step response")
    tail = max(3, n // 10)
    after = float(np.median(u[-tail:]))
    head = u[: max(2, n // 50)]
    before0 = float(np.median(head))
    mid = 0.5 * (before0 + after)
    sgn = 1.0 if after >= before0 else -1.0
    crossed = np.nonzero(sgn * (u - mid) > 0)[0]
    scatter = float(np.std(u[-tail:])) + float(np.std(head))
    if len(crossed) == 0 or abs(after - before0) <= 5 * scatter or after == before0:
        raise FitError(f"{path or 'log'}: no step found in the input (it is constant or noisy); "
                       "the stage needs one step per log")
    k = int(crossed[0])
    if k < 2:
        raise FitError(f"{path or 'log'}: the input step is at the first sample: the log needs "
                       "some samples at rest before the step")
    before = float(np.median(u[:k]))
    return StepInfo(k, float(t[k]), before, after)


#: a plateau shorter than this many samples is a glitch, not a step
MIN_PLATEAU_SAMPLES = 10
#: an input change larger than this many noise std of the input (its white noise, from the
#: sample-to-sample differences) divided by the square root of the samples averaged on each side
CHANGE_SIGMAS = 8.0
#: ... and than this fraction of the input's range (an ADC's one-count flicker is not a step)
MIN_STEP_FRACTION = 0.01
#: changes are looked for between single samples, then between the means of 2, 4, ... samples
#: on each side while the noise hides a change of :data:`SCALE_FRACTION` of the input's range
#: (a measured, noisy input), up to :data:`MAX_SCALE` samples
MAX_SCALE = 32
SCALE_FRACTION = 0.05


#: the input's noise is estimated in blocks of this many samples, the noisiest quarter's
#: (:func:`_input_noise`; on white noise 8 % above its std)
NOISE_BLOCK = 128
NOISE_QUANTILE = 75.0


def _mad_noise(d: np.ndarray) -> float:
    """White-noise std of a signal from its first differences ``d``: their MAD over sqrt(2)."""
    return mad_std(d) / math.sqrt(2.0)


def _input_noise(u: np.ndarray) -> float:
    """White-noise std of an input (its unit), robust to its steps and ramps: the MAD of its
    first differences over sqrt(2) (the whole log), or of its second differences over sqrt(6)
    in blocks of :data:`NOISE_BLOCK` samples, the :data:`NOISE_QUANTILE` percentile of the
    blocks', whichever is larger (a PWM average rippling in proportion to the duty is noisy on
    some plateaus only; a ramp has no second differences)."""
    d = np.diff(u)
    whole = _mad_noise(d)
    nb = (len(d) - 1) // NOISE_BLOCK
    if nb < 2:
        return whole
    d2 = np.diff(d)[:nb * NOISE_BLOCK].reshape(nb, NOISE_BLOCK)
    mad = np.median(np.abs(d2 - np.median(d2, axis=1, keepdims=True)), axis=1)
    return max(whole, 1.4826 * float(np.percentile(mad, NOISE_QUANTILE)) / math.sqrt(6.0))


@dataclass
class _Detector:
    """How changes are told from noise in one input: its white-noise std ``sig`` (unit of the
    input), the floor no change is below (``floor``), the scales (samples averaged on each side
    of a change) it is looked for at."""

    sig: float
    floor: float
    scales: tuple[int, ...]

    def thr(self, w: int) -> float:
        """The smallest change seen at scale ``w``: CHANGE_SIGMAS noise std of a w-sample mean."""
        return max(CHANGE_SIGMAS * self.sig / math.sqrt(w), self.floor)

    @property
    def coarsest(self) -> int:
        return self.scales[-1]


def _detector(u: np.ndarray) -> _Detector:
    """The input's noise, floor and scales: coarser scales while CHANGE_SIGMAS noise std of a
    w-sample mean exceed :data:`SCALE_FRACTION` of the input's range (1st to 99th percentile);
    a noise-free input is looked at sample to sample only."""
    sig = _input_noise(u)
    # a measured input quantised by its ADC has no sample-to-sample noise most of the time
    # (sig = 0): its one-count flicker is not a step, hence a floor of a fraction of the range
    floor = max(1e-9 * max(float(np.max(np.abs(u))), 1e-300),
                MIN_STEP_FRACTION * float(np.ptp(u)))
    scales = [1]
    if sig > 0:
        span = float(np.percentile(u, 99) - np.percentile(u, 1))
        while (CHANGE_SIGMAS * sig / math.sqrt(scales[-1]) > SCALE_FRACTION * span
               and 2 * scales[-1] <= min(MAX_SCALE, len(u) // 4)):
            scales.append(2 * scales[-1])
    return _Detector(sig, floor, tuple(scales))


def _run_peaks(x: np.ndarray, above: np.ndarray) -> np.ndarray:
    """The index of the largest ``x`` in every run of consecutive ``above`` samples."""
    idx = np.flatnonzero(above)
    if len(idx) == 0:
        return idx
    run = np.concatenate(([0], np.cumsum(np.diff(idx) > 1)))
    starts = np.flatnonzero(np.concatenate(([True], np.diff(run) > 0)))
    top = np.maximum.reduceat(x[idx], starts)
    hit = np.flatnonzero(x[idx] == top[run])
    _, first = np.unique(run[hit], return_index=True)
    return idx[hit[first]]


def _split(c: np.ndarray, p: int, w: int) -> int:
    """The least-squares single change point (first sample of the new level) in the 2w samples
    around ``p``; ``c``: the input's cumulative sum with a leading 0."""
    a, b = p - w, p + w
    j = np.arange(a + 1, b)
    left = (c[j] - c[a]) / (j - a)
    right = (c[b] - c[j]) / (b - j)
    gain = (j - a) * (b - j) / (b - a) * (left - right) ** 2
    return int(j[np.argmax(gain)])


def _changes(u: np.ndarray, det: _Detector) -> np.ndarray:
    """Sorted samples ``k`` where the input changes (u[k] differs from u[k-1] beyond the noise at
    the finest scale that shows it; a change seen at a coarser scale is located by
    least squares between its two levels)."""
    found = np.nonzero(np.abs(np.diff(u)) > det.thr(1))[0] + 1
    if det.coarsest == 1:
        return found
    c = np.concatenate(([0.0], np.cumsum(u)))
    for w in det.scales[1:]:
        k = np.arange(w, len(u) - w + 1)
        d = np.abs((c[k + w] - c[k]) - (c[k] - c[k - w])) / w
        peaks = k[_run_peaks(d, d > det.thr(w))]
        peaks = np.array([_split(c, int(p), w) for p in peaks
                          if len(u) - w >= p >= w], int)
        if len(peaks) == 0:
            continue
        pos = np.searchsorted(found, peaks)
        near = np.zeros(len(peaks), bool)
        for side in (pos - 1, pos):
            ok = (side >= 0) & (side < len(found))
            near[ok] |= np.abs(found[side[ok]] - peaks[ok]) <= w
        found = np.unique(np.concatenate((found, peaks[~near])))
    return found


def _segments(ch: np.ndarray, n: int) -> list[tuple[int, int, int]]:
    """(transition start, plateau start, plateau end) of every interval between input changes
    ``ch`` (sorted samples); consecutive changing samples (a ramped edge) form one transition."""
    out, start, k = [], 0, 0
    bounds = []
    while k < len(ch):
        j = k
        while j + 1 < len(ch) and ch[j + 1] - ch[j] <= 2:
            j += 1
        bounds.append((int(ch[k]), int(ch[j])))
        k = j + 1
    prev = 0
    for a, b in bounds:
        out.append((start, prev, a))
        start, prev = a, b
    out.append((start, prev, n))
    return out


def _spread(x: np.ndarray, w: int) -> float:
    """The 95 % range of ``x`` averaged over ``w`` samples (the noise averaged, the wave kept)."""
    w = max(1, min(w, len(x) // 4))
    if w > 1:
        c = np.concatenate(([0.0], np.cumsum(x)))
        x = (c[w:] - c[:-w]) / w
    return float(np.percentile(x, 97.5) - np.percentile(x, 2.5))


def _level(u: np.ndarray, seg: tuple[int, int, int]) -> float:
    """A plateau's input: the mean of its samples (noise and ripple averaged)."""
    a, b, e = seg
    return float(np.mean(u[b:e])) if e > b else float(u[a])


def _flat(u: np.ndarray, b: int, e: int, du: float, det: _Detector) -> bool:
    """Whether the input holds its level from ``b`` to ``e``: its variation, the noise averaged
    over the detector's coarsest scale, under a tenth of the step ``du`` or a fifth of the level
    itself (a PWM average ripples in proportion to the duty: a supply's +-10 %), plus 6 noise
    std of that average."""
    w = det.coarsest
    level = float(np.mean(u[b:e]))
    tol = max(0.1 * abs(du), 0.2 * abs(level)) + 6 * det.sig / math.sqrt(
        max(1, min(w, (e - b) // 4)))
    return _spread(u[b:e], w) <= tol


def _line(x: np.ndarray, at: float) -> tuple[float, float]:
    """The least-squares line through ``x`` (samples 0..len-1): its value at sample ``at`` and
    its change over ``x`` (slope times length)."""
    k = np.arange(len(x), dtype=float)
    slope, icpt = np.polyfit(k, x, 1) if len(x) > 1 else (0.0, float(x[0]))
    return float(icpt + slope * at), float(slope * len(x))


def _jump(u: np.ndarray, prev: tuple[int, int, int], seg: tuple[int, int, int],
          det: _Detector) -> bool:
    """For a noisy input (changes looked for at coarser scales than one sample), whether the
    change from plateau ``prev`` to ``seg`` is a discontinuity, not a ramp or wave cut in two:
    the straight lines through the two plateaus, extended to the transition, part by more than
    :data:`CHANGE_SIGMAS` standard errors, and each plateau's own trend is under a tenth of
    that jump plus 4 of its standard errors. Always true for a noise-free input."""
    if det.coarsest == 1:
        return True
    (_, b0, e0), (a, b, e) = prev, seg
    if e0 - b0 < 2:
        return False
    mid = 0.5 * (a + b)
    left, trend0 = _line(u[b0:e0], mid - b0)
    right, trend = _line(u[b:e], mid - b)
    gap = right - left
    if not abs(gap) > CHANGE_SIGMAS * 2 * det.sig * math.sqrt(1 / (e0 - b0) + 1 / (e - b)):
        return False
    return all(abs(tr) <= 0.1 * abs(gap) + 4 * det.sig * math.sqrt(12 / m)
               for tr, m in ((trend0, e0 - b0), (trend, e - b)))


def _merge(u: np.ndarray, segs: list[tuple[int, int, int]], det: _Detector,
           thr: float) -> list[tuple[int, int, int]]:
    """For a noisy input, the intervals between changes with every change that is no jump taken
    out: first those within ``thr`` of the level before (a slow ripple or the noise seen at a
    coarse scale), then a ramp or wave cut in two (:func:`_jump`), so that neither cuts a
    plateau short. A noise-free input's are kept."""
    if det.coarsest == 1:
        return segs
    segs = _merge_pass(segs, lambda p, q: abs(_level(u, q) - _level(u, p)) > thr)
    return _merge_pass(segs, lambda p, q: _jump(u, p, q, det))


def _merge_pass(segs, is_jump) -> list[tuple[int, int, int]]:
    """``segs`` with each change for which ``is_jump(previous, next)`` is false taken out."""
    out = [segs[0]]
    for seg in segs[1:]:
        prev = out[-1]
        if is_jump(prev, seg):
            out.append(seg)
        else:
            out[-1] = (prev[0], prev[1], seg[2])
    return out


def find_steps(t: np.ndarray, u: np.ndarray, path: str | None = None, *,
               at_start: bool = False) -> list[StepInfo]:
    """Every step in input ``u`` (e.g. V): an interval of constant input after a change, up to
    the next change (up or down, several per log; a last plateau of a few samples is a glitch).

    Changes are told from the input's own noise (:func:`_input_noise`, robust): a jump between
    samples, or for a noisy measured input a jump between the means of up to
    :data:`MAX_SCALE` samples on each side (:func:`_changes`); a plateau's level is its mean.
    Onset: the first sample of the transition past half-way between the levels (for a
    zero-order-held input, the sample of the jump; for a noisy one, the least-squares change
    point). Raises :class:`FitError` when the input holds no plateau after a clear change
    (constant, noisy, or varying all the time: ramps, sines).

    ``at_start``: the caller knows the system was at rest with the input 0 before the log (a
    rig that applies the input from its first logged sample): a nonzero first plateau is then a
    step from 0 at the first sample.
    """
    u = np.asarray(u, float)
    n = len(u)
    if n < MIN_PLATEAU_SAMPLES:
        raise FitError(f"{path}: too short ({n} samples) to hold a step response")
    det = _detector(u)
    thr = max(det.thr(det.coarsest), 5 * det.sig / math.sqrt(det.coarsest))
    segs = _merge(u, _segments(_changes(u, det), n), det, thr)
    levels = [_level(u, s) for s in segs]
    steps = []
    a0, b0, e0 = segs[0]
    if (at_start and b0 == 0 and e0 >= MIN_PLATEAU_SAMPLES and abs(levels[0]) > thr
            and _flat(u, 0, e0, levels[0], det)):  # held, not a varying input never cut
        steps.append(StepInfo(0, float(t[0]), 0.0, levels[0], e0, 0))
    for j in range(1, len(segs)):
        a, b, e = segs[j]
        lev, before = levels[j], levels[j - 1]
        du = lev - before
        if (e - b < max(MIN_PLATEAU_SAMPLES, det.coarsest) or abs(du) <= thr
                or not _flat(u, b, e, du, det) or not _jump(u, segs[j - 1], segs[j], det)):
            continue  # a glitch, a change within the noise, or a ramp or wave between changes
        mid = 0.5 * (before + lev)
        sg = 1.0 if du > 0 else -1.0
        k = a + int(np.argmax(sg * (u[a:b + 1] - mid) > 0))
        t0 = _averaged_edge(t, u, k, before, lev, det) if det.sig == 0 else float(t[k])
        steps.append(StepInfo(k, t0, before, lev, e, segs[j - 1][0],
                              _level_se(det, segs[j - 1])))
    if not steps:
        raise FitError(f"{path or 'log'}: no step found in the input (it is constant, noisy or "
                       "never held after a change); the stage needs intervals of constant "
                       "input after a change")
    return steps


def _averaged_edge(t: np.ndarray, u: np.ndarray, k: int, before: float, after: float,
                   det: _Detector) -> float:
    """The instant [s] of a held input's edge that falls inside a sample period: a noise-free
    input averaged over each step (a log put on a measurement's clock or a loop-timed one's
    grid, :mod:`pmdcid.io.clock`) shows it as one sample ``m`` between the levels, the mean over
    ``[t[m], t[m+1])``; the edge is then ``t[m+1] - frac (t[m+1] - t[m])`` with ``frac`` the
    sample's fraction of the way to the new level (the input's integral kept). Otherwise
    ``t[k]``, the onset sample's own instant."""
    du = after - before
    tol = max(det.floor, 1e-9 * abs(du))

    def between(x: float) -> bool:
        return min(abs(x - before), abs(x - after)) > tol and (x - before) * (after - x) > 0

    m = k - 1 if k > 0 and between(u[k - 1]) else k
    if not between(u[m]) or m < 1 or m + 2 > len(u) or abs(u[m - 1] - before) > tol \
            or abs(u[m + 1] - after) > tol:
        return float(t[k])
    frac = (u[m] - before) / du
    return float(t[m + 1] - frac * (t[m + 1] - t[m]))


def held_head(u: np.ndarray, step: StepInfo) -> bool:
    """Whether the input holds the level of ``step``'s plateau before from the log's first
    sample to the step (``step`` the first of :func:`find_steps`): one plateau, flat within
    the input's noise (:func:`_flat`)."""
    u = np.asarray(u, float)
    if step.prev_start != 0 or step.onset < 2:
        return False
    return _flat(u, 0, step.onset, step.amplitude, _detector(u))


def _level_se(det: _Detector, seg: tuple[int, int, int]) -> float:
    """Standard error of a plateau's mean input from the input's white noise."""
    a, b, e = seg
    return det.sig / math.sqrt(max(e - b, 1))


#: an input is held (piecewise constant) when this fraction of its samples lie on the
#: plateaus of its steps or on the level before the first one
HELD_FRACTION = 0.9


def held_steps(t: np.ndarray, u: np.ndarray) -> list[StepInfo]:
    """The steps of an input held at levels (a step, a staircase, levels, an APRBS): every step
    :func:`find_steps` finds, when at least :data:`HELD_FRACTION` of the samples lie on their
    plateaus or on the level before the first. An input that varies between its levels (a
    ramp, a sine), or holds no step, gives []. Robust to a noisy measured input: a change is
    a jump beyond :data:`CHANGE_SIGMAS` noise std of the means it is seen between
    (:func:`find_steps`)."""
    try:
        steps = find_steps(t, u)
    except FitError:
        return []
    u = np.asarray(u, float)
    n = len(u)
    first = steps[0]
    du = abs(first.amplitude)
    head = first.onset - _blend_before(u, first)
    flat_head = head > 0 and _flat(u, 0, head, du, _detector(u))
    covered = (first.onset if flat_head else 0) + sum(
        (s.end if s.end is not None else n) - s.onset for s in steps)
    return steps if covered >= HELD_FRACTION * n else []


def _blend_before(u: np.ndarray, step: StepInfo) -> int:
    """1 when the sample before ``step``'s onset lies strictly between its two levels (a blend
    of them: a loop-timed log put on a uniform grid holds each row's input from its instant,
    docs/io.md "Clocks", so the sample the change falls in averages the two), else 0. Such a
    sample is the step's, not the level's before it: read as the level's, a step whose change
    fell early in its sample (2.7 V, the blend 0.54 V) had no flat level before it, and the
    log was called rich (bench/newrigs.py lego seed 23)."""
    k = step.onset - 1
    if k < 1:
        return 0
    lo, hi = sorted((step.before, step.after))
    return int(lo < u[k] < hi)


@dataclass
class HeldInput:
    """A noisy input held at levels with each plateau replaced by its mean (``u``, the
    transitions as logged) and the plateaus: (first sample, end, standard error of the mean
    [unit of the input])."""

    u: np.ndarray
    plateaus: list[tuple[int, int, float]]


def held_levels(t: np.ndarray, u: np.ndarray) -> HeldInput | None:
    """A noisy input held at levels (:func:`held_steps`) with each plateau replaced by its mean
    (the noise and a fast ripple averaged); None for an input not held at levels, one whose
    changes are seen sample to sample (nothing to average), or one whose plateaus vary more
    than their noise when averaged (:func:`_white`: a slow ripple the armature follows)."""
    u = np.asarray(u, float)
    det = _detector(u)
    if det.coarsest == 1:
        return None
    steps = held_steps(t, u)
    if not steps:
        return None
    spans = [(0, steps[0].onset, steps[0].before)] if steps[0].onset > 0 else []
    spans += [(s.onset, s.end if s.end is not None else len(u), s.after) for s in steps]
    if not all(_white(u[a:e], det) for a, e, _ in spans):
        return None
    out = u.copy()
    for a, e, level in spans:
        out[a:e] = level
    return HeldInput(out, [(a, e, det.sig / math.sqrt(e - a)) for a, e, _ in spans])


def _white(x: np.ndarray, det: _Detector) -> bool:
    """Whether a plateau varies as its white noise does: the means of its blocks of the
    detector's coarsest scale scatter by at most 1.5 times sig/sqrt(w), plus 3 standard errors
    of that scatter."""
    w = det.coarsest
    m = len(x) // w
    if m < 4:
        return True
    means = x[:m * w].reshape(m, w).mean(axis=1)
    return float(np.std(means, ddof=1)) <= det.sig / math.sqrt(w) * (1.5 + 3 / math.sqrt(2 * m))


@dataclass
class StrejcResult:
    """Strejc's graphical method on a normalised step response.

    ``gain`` response change per input change; ``tau`` [s] first-order time constant (time to
    63.2 %); ``tu``/``tn`` [s] delay and rise time of the inflection tangent; ``order`` the
    number of equal lags whose Tu/Tn is nearest.
    """

    gain: float
    tau: float
    tu: float
    tn: float
    order: int
    final: float
    initial: float

    @property
    def ratio(self) -> float:
        return self.tu / self.tn if self.tn > 0 else math.nan


def _smooth(y: np.ndarray, w: int) -> np.ndarray:
    if w <= 1:
        return y
    k = np.ones(w) / w
    pad = np.concatenate([np.full(w, y[0]), y, np.full(w, y[-1])])
    return np.convolve(pad, k, mode="same")[w:-w]


def strejc(t: np.ndarray, y: np.ndarray, step: StepInfo, settle_fraction: float = 0.2
           ) -> StrejcResult:
    """Strejc's method on response ``y`` to the step ``step`` (the paper's identification).

    Gain from the levels before the onset and over the last ``settle_fraction`` of the log;
    tangent at the inflection (largest slope of the lightly smoothed response) gives Tu and Tn.
    """
    y = np.asarray(y, float)
    k0 = step.onset
    y0 = float(np.median(y[:k0])) if k0 > 0 else float(y[0])  # a step at the first sample
    tail = max(3, int(len(y) * settle_fraction))
    y1 = float(np.median(y[-tail:]))
    dy = y1 - y0
    du = step.amplitude
    tt = t[k0:] - step.t0
    yn = (y[k0:] - y0) / dy if dy != 0 else np.zeros(len(tt))
    dt = float(t[1] - t[0])
    # time to 63.2 %: first crossing, linearly interpolated, on a lightly smoothed response
    ys = _smooth(yn, 3)
    above = np.nonzero(ys >= 1 - math.exp(-1))[0]
    if len(above) == 0:
        tau = math.nan
    else:
        j = int(above[0])
        if j == 0:
            tau = 0.5 * dt
        else:
            a, b = ys[j - 1], ys[j]
            tau = tt[j - 1] + (1 - math.exp(-1) - a) / (b - a) * dt if b != a else tt[j]
    # inflection tangent: slope by a local quadratic (Savitzky-Golay) over ~0.3 tau
    from pmdcid.identify.filters import savgol

    w = max(5, int(round(0.3 * tau / dt)) | 1) if math.isfinite(tau) else 5
    w = min(w, len(yn) - (1 - len(yn) % 2))
    if w >= 5:
        yw = savgol(yn, w, 2)
        slope = savgol(yn, w, 2, deriv=1, delta=dt)
    else:
        yw, slope = yn, np.gradient(yn, dt)
    span = np.nonzero(yw < 0.9)[0]
    lim = int(span[-1]) + 1 if len(span) else len(yw)
    j = int(np.argmax(slope[:max(lim, 2)]))
    s = float(slope[j])
    if s > 0:
        tu = max(0.0, tt[j] - yw[j] / s)
        tn = 1.0 / s
    else:
        tu, tn = math.nan, math.nan
    ratio = tu / tn if tn and math.isfinite(tn) else math.nan
    order = 1 + int(np.argmin([abs(ratio - r) for r in STREJC_TU_TN])) if math.isfinite(
        ratio) else 1
    gain = dy / du if du else math.nan
    return StrejcResult(gain, float(tau), float(tu), float(tn), order, y1, y0)


def first_order(s: np.ndarray, y0: float, dy: float, tau: float, d: float) -> np.ndarray:
    """First-order step response: y0 + dy (1 - exp(-(s - d)/tau)) for s > d, y0 before (s [s])."""
    x = np.clip(s - d, 0.0, None)
    return y0 + dy * -np.expm1(-x / max(tau, 1e-300))


def two_lag(s: np.ndarray, tau_m: float, tau_e: float, beta: float = 1.0) -> np.ndarray:
    """Unit step response of 1/((tau_m p + 1)) driven by the forcing 1 - beta exp(-s/tau_e).

    With beta = 1 this is the two-lag (tau_m, tau_e) response; beta < 1 is a rotor that breaks
    free when the current has already risen partly (forcing jumps at s = 0). s [s], s >= 0.
    """
    s = np.clip(s, 0.0, None)
    if abs(tau_m - tau_e) < 1e-9 * tau_m:
        tau_e = tau_e * (1 - 1e-6)
    a = beta * tau_e / (tau_m - tau_e)
    return 1.0 + a * np.exp(-s / tau_e) - (1.0 + a) * np.exp(-s / tau_m)


@dataclass
class CurveFit:
    """Least-squares fit of a step-response model: values, standard errors, residual std."""

    names: tuple[str, ...]
    values: np.ndarray
    stderr: np.ndarray
    sigma: float
    ndata: int
    success: bool

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def se(self, name: str) -> float:
        return float(self.stderr[self.names.index(name)])


def lsq(fun, x0, lo, hi, names, ndata: int | None = None, segments=None) -> CurveFit:
    """scipy ``least_squares`` (TRF) on residual ``fun(x)``; standard errors from J'J scaled by
    s^2, in the sandwich that allows for a residual correlated in time (:mod:`.covariance`).
    ``segments``: (log, first, end) rows of each log in the residual (default: one log)."""
    x0 = np.clip(np.asarray(x0, float), lo, hi)
    scale = scale_of(x0)
    sol = solve(lambda z: fun(z * scale), x0 / scale, lo / scale, hi / scale, scale=scale,
                what="curve fit")
    x = sol.x
    r = sol.fun
    n = len(r) if ndata is None else ndata
    dof = max(n - len(x), 1)
    s2 = float(r @ r) / dof
    try:
        cov = white_covariance(sol.jac, r, dof)
        cov, _ = block_covariance(sol.jac, r, segments or [(0, 0, len(r))], cov)
        se = standard_errors(cov)
    except np.linalg.LinAlgError:
        se = np.full(len(x), math.nan)
    return CurveFit(tuple(names), x, se, math.sqrt(s2), n, bool(sol.success))


def fit_first_order(t: np.ndarray, y: np.ndarray, step: StepInfo, st: StrejcResult,
                    dead_time: bool = True) -> CurveFit:
    """Refine Strejc's first-order model by least squares: y0, dy, tau [s], d [s] (dead time)."""
    s = t - step.t0
    dt = float(t[1] - t[0])
    tau0 = st.tau if math.isfinite(st.tau) and st.tau > 0 else 0.1 * (t[-1] - step.t0)
    dy0 = st.final - st.initial
    names = ("y0", "dy", "tau", "d")
    span = float(t[-1] - step.t0)
    lo = np.array([-np.inf, -np.inf, 0.05 * dt, 0.0])
    hi = np.array([np.inf, np.inf, 10 * span, 0.5 * span if dead_time else 1e-12 * dt])
    # two starts for the dead time (Strejc's tangent, capped at half the time constant, and 0):
    # on a quantised or rippled speed the tangent can be far off, and the cost has side minima
    d_starts = {0.0}
    if dead_time and math.isfinite(st.tu):
        d_starts.add(min(st.tu, 0.5 * tau0))
    fits = [lsq(lambda x: first_order(s, *x) - y, [st.initial, dy0, tau0, d0], lo, hi, names)
            for d0 in sorted(d_starts)]
    return min(fits, key=lambda cf: cf.sigma)


def despike(y: np.ndarray, sigmas: float = 20.0) -> tuple[np.ndarray, np.ndarray]:
    """Isolated spikes (a sample far from the median of its 5 neighbours: a counter wrap, a
    serial glitch) replaced by that median. Returns (cleaned copy, indices replaced). A spike is
    more than ``sigmas`` robust std of the signal's deviation from its running median, and more
    than a fifth of the signal's range away from it (a step edge is not a spike)."""
    from pmdcid.identify.filters import medfilt5

    y = np.asarray(y, float)
    if len(y) < 5:
        return y.copy(), np.zeros(0, int)
    med = medfilt5(y)
    dev = y - med
    sd = 1.4826 * float(np.median(np.abs(dev)))
    rng = float(np.percentile(med, 99) - np.percentile(med, 1))
    bad = np.nonzero(np.abs(dev) > max(sigmas * sd, 0.2 * rng, 1e-300))[0]
    out = y.copy()
    out[bad] = med[bad]
    return out, bad


def residual_std(t, y, step: StepInfo) -> float:
    """Noise std of ``y`` from the samples before the step (robust), same unit as y."""
    pre = np.asarray(y[: step.onset], float)
    if len(pre) < 5:
        return math.nan
    return mad_std(pre)
