"""Speed from position (and position from speed) for logs that lack one of them.

Speed from position: the angle [rad] (or position [m]) is low-pass filtered by a Butterworth
filter of order :data:`ORDER` run forwards and backwards (``scipy.signal.sosfiltfilt``: zero phase,
so no lag, effective order doubled), then differentiated by central differences
(``numpy.gradient``). The same filtered signal differentiated twice gives the acceleration used
by the inverse-dynamics estimator. The cut-off [Hz] is the user's (``--cutoff HZ``) or
:func:`default_cutoff` (a tenth of the sample rate, at most 100 Hz).

Position from speed: cumulative trapezoid of the speed [rad/s] from 0 at the first sample
(the angle's origin is arbitrary; the simulator starts from 0 too).

Derived columns are listed in ``Log.derived`` so that commands can say so and avoid treating
them as independent measurements.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import LogError

#: order of the Butterworth filter (before the forward-backward pass doubles it)
ORDER = 4
#: default cut-off as a fraction of the sample rate, and its ceiling [Hz]
DEFAULT_CUTOFF_FRACTION = 0.1
DEFAULT_CUTOFF_MAX_HZ = 100.0


def default_cutoff(dt: float) -> float:
    """Default cut-off [Hz] for a sample period ``dt`` [s]: min(0.1/dt, 100 Hz).

    A tenth of the sample rate keeps the filter well inside the Nyquist band; 100 Hz is above
    the mechanical bandwidth of practically every motor-and-load (mechanical time constants of
    a few milliseconds and more) while rejecting encoder quantisation noise.
    """
    return min(DEFAULT_CUTOFF_FRACTION / dt, DEFAULT_CUTOFF_MAX_HZ)


def mad_std(x: np.ndarray) -> float:
    """The robust std of ``x`` (its unit): 1.4826 times its median absolute deviation, the std
    of normal samples. Of a signal's first differences, over sqrt(2), it is the signal's
    white-noise std; of its second differences, over sqrt(6)."""
    x = np.asarray(x, dtype=float)
    return 1.4826 * float(np.median(np.abs(x - np.median(x))))


#: two samples closer than this many units in the last place of the signal's largest value are
#: equal: the rounding of a linear interpolation between equal samples (a few ulp), far below
#: any sensor's resolution
HELD_ULPS = 1000.0


def rounding(x: np.ndarray) -> float:
    """The size of rounding in ``x`` [its unit]: :data:`HELD_ULPS` units in the last place of
    its largest value (0 for an empty signal)."""
    return HELD_ULPS * float(np.spacing(np.max(np.abs(x)))) if x.size else 0.0


def held_samples(x: np.ndarray) -> np.ndarray:
    """Boolean mask of the samples of ``x`` equal (up to rounding, :data:`HELD_ULPS`) to a
    neighbour: a signal held still there (a quantised speed at rest, a held input)."""
    x = np.asarray(x, dtype=float)
    same = np.abs(np.diff(x)) <= rounding(x)
    out = np.zeros(x.size, dtype=bool)
    out[:-1] |= same
    out[1:] |= same
    return out


def moving_noise_std(x: np.ndarray) -> float:
    """Robust white-noise std of ``x`` from the MAD of its second differences taken only where
    none of their three samples is held (:func:`held_samples`); 0 where there are none.

    A signal held exactly still has no noise to read there, and when it holds still for half
    the log (a quantised speed at rest) the MAD over every sample is 0. The ends of a held
    stretch are left out too: an edge put on another clock by interpolation makes a partial
    first step there, no noise.
    """
    x = np.asarray(x, dtype=float)
    if x.size < 5:
        return 0.0
    h = held_samples(x)
    free = ~(h[:-2] | h[1:-1] | h[2:])
    if not free.any():
        return 0.0
    # RMS over the log: none where it is held (reduced chi-square 1 for a model that fits)
    return mad_std(np.diff(x, 2)[free]) / math.sqrt(6.0) * math.sqrt(float(np.mean(free)))


#: a change within this fraction of the quantum of a whole number of quanta is on the lattice:
#: wide enough for the rounding of printed values (a quantum read as 0.76690 where it is
#: 0.766990, its multiples printed to five decimals), far narrower than the arbitrary
#: fractions of a quantum an interpolated edge leaves
LATTICE_TOL = 0.05


def on_lattice(x: np.ndarray) -> bool:
    """Whether every change of ``x`` above rounding (:data:`HELD_ULPS`) is a whole number of
    one quantum (:data:`LATTICE_TOL`), the quantum read as the median of the smallest changes
    (those within 1.5 times the smallest): a quantised signal read on its own clock (encoder
    counts times a scale, printed or not). One put on another clock by linear interpolation
    is not."""
    x = np.asarray(x, dtype=float)
    steps = np.abs(np.diff(x))
    steps = steps[steps > rounding(x)]
    if not steps.size:
        return True
    quantum = float(np.median(steps[steps <= 1.5 * float(np.min(steps))]))
    r = steps / quantum
    return bool(np.all(np.abs(r - np.round(r)) <= LATTICE_TOL))


def noise_std(x: np.ndarray) -> float:
    """Robust white-noise std of a signal (its unit) from the MAD of its second difference,
    at least quantum/sqrt(12) for a quantised signal (encoder angle).

    Where that reading fails, and only there, the noise is read where the signal moves
    (:func:`moving_noise_std`): a signal that holds still for half the log (a quantised speed
    at rest) has a MAD of rounding's size, and once put on another clock by interpolation it is
    off its lattice (:func:`on_lattice`), so its smallest step is an interpolation's rounding,
    no quantum. Elsewhere the MAD stands: where a quantised signal's repeats are its noise (a
    steady speed between two counts), reading only where it moves would overstate it.
    """
    x = np.asarray(x, dtype=float)
    if len(x) < 5:
        return 0.0
    d2 = np.diff(x, 2)
    s = mad_std(d2) / math.sqrt(6.0)
    degenerate = s <= rounding(x)
    steps = np.abs(np.diff(x))
    steps = steps[steps > 0]
    if len(steps):
        s = max(s, float(np.min(steps)) / math.sqrt(12.0))
    if degenerate and not on_lattice(x):
        s = max(s, moving_noise_std(x))
    return s


def derivative_noise_gain(dt: float, cutoff_hz: float, nder: int, order: int = ORDER) -> float:
    """Std of the ``nder``-th derivative (filtered, central differences) of unit white noise
    sampled every ``dt`` [s]: [1/s^nder]."""
    from scipy.signal import sosfreqz

    w, h = sosfreqz(butterworth(order, cutoff_hz, dt), worN=2048)
    g2 = np.abs(h) ** 4 * (np.sin(w) / dt) ** (2 * nder)
    return float(np.sqrt(np.mean(g2)))


def choose_cutoff(x: np.ndarray, dt: float, nder: int = 2, max_noise: float = 0.1,
                  ceiling: float | None = None) -> float:
    """Highest cut-off [Hz] (from :func:`default_cutoff` down by steps of sqrt(2)) at which the
    sensor noise of ``x`` makes up at most ``max_noise`` of the std of its ``nder``-th
    derivative.

    Noise in a regressor biases least squares towards zero (errors in variables): with 10 %
    noise the inertia from inverse dynamics is about 1 % low. A coarse encoder or fast sampling
    thus gets a lower cut-off than :func:`default_cutoff`.
    """
    fc = default_cutoff(dt) if ceiling is None else ceiling
    floor = fc / 64.0
    sigma = noise_std(x)
    if sigma == 0.0:
        return fc
    while fc > floor:
        th = lowpass(x, dt, fc)
        d = th
        for _ in range(nder):
            d = np.gradient(d, dt)
        edge = min(int(5.0 / (fc * dt)), len(d) // 10)
        sd = float(np.std(d[edge:len(d) - edge]))
        if sigma * derivative_noise_gain(dt, fc, nder) <= max_noise * sd:
            return fc
        fc /= math.sqrt(2.0)
    return floor


#: lowest cut-off as a fraction of the sample rate: below it the filter's design is numerically
#: singular (a 1e-9 Hz cut-off at 1 kHz), and no motor signal is that slow
MIN_CUTOFF_FRACTION = 1e-5


def check_cutoff(cutoff_hz: float, dt: float, path: str | None = None) -> float:
    """Validate a cut-off [Hz] against the sample period ``dt`` [s]; raises :class:`LogError`."""
    nyq = 0.5 / dt
    if not (math.isfinite(cutoff_hz) and 0 < cutoff_hz < nyq):
        raise LogError(
            f"filter cut-off {cutoff_hz:g} Hz must be positive and below the Nyquist frequency "
            f"{nyq:g} Hz of this log (give --cutoff HZ)",
            path,
        )
    low = MIN_CUTOFF_FRACTION / dt
    if cutoff_hz < low:
        raise LogError(f"filter cut-off {cutoff_hz:g} Hz is too low for this log's sample rate "
                       f"{1 / dt:g} Hz: give --cutoff of at least {low:.3g} Hz (the default is "
                       f"{default_cutoff(dt):g} Hz)", path)
    return float(cutoff_hz)


def butterworth(order: int, cutoff_hz: float, dt: float) -> np.ndarray:
    """The low-pass Butterworth filter of ``order`` with its cut-off at ``cutoff_hz`` [Hz], for
    samples every ``dt`` [s], in second-order sections."""
    return _design(int(order), float(cutoff_hz), float(dt))[0].copy()


@functools.lru_cache(maxsize=64)
def _design(order: int, cutoff_hz: float, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """(second-order sections, their steady-state initial conditions per unit input), kept: a
    fit that compares a simulated angle's speed with a measured one filters every evaluation
    the same way, and designing the filter took four times as long as filtering with it."""
    from scipy.signal import butter, sosfilt_zi

    sos = butter(order, cutoff_hz, btype="low", fs=1.0 / dt, output="sos")
    return sos, sosfilt_zi(sos)


def lowpass(x: np.ndarray, dt: float, cutoff_hz: float, order: int = ORDER) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` (any unit) sampled every ``dt`` [s].

    ``scipy.signal.butter(order, cutoff)`` in second-order sections (numerically safe at cut-offs
    far below the sample rate) applied forwards and backwards with odd-reflection padding of
    3*order samples (as MATLAB's ``filtfilt``), shortened for very short signals: the steps of
    ``scipy.signal.sosfiltfilt``, bit for bit, with the design kept (:func:`_design`) and each
    pass run by :func:`_sos_pass`'s choice.
    """
    x = np.asarray(x, dtype=float)
    sos, zi = _design(int(order), float(cutoff_hz), float(dt))
    pad = min(3 * order, len(x) - 1)
    ext = x if pad <= 0 else np.concatenate(
        (2 * x[0] - x[pad:0:-1], x, 2 * x[-1] - x[-2:-(pad + 2):-1]))
    one_pass = _sos_pass()
    y = one_pass(sos, ext, zi * ext[0])
    y = one_pass(sos, y[::-1], zi * y[-1])[::-1]
    return np.ascontiguousarray(y if pad <= 0 else y[pad:len(y) - pad])


def _public_sos_pass(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """One forward pass of the sections ``sos`` over ``x`` from the state ``zi``:
    ``scipy.signal.sosfilt``."""
    from scipy.signal import sosfilt

    return sosfilt(sos.copy(), x, zi=zi)[0]  # sosfilt takes a writeable array


def _core_sos_pass(sos: np.ndarray, x: np.ndarray, zi: np.ndarray) -> np.ndarray:
    """:func:`_public_sos_pass` by the compiled loop ``scipy.signal.sosfilt`` calls, without
    its argument checks (a tenth of the time on a log of a few hundred samples: a fit that
    compares a simulated angle's derived speed filters every log at every evaluation; on the
    lego-ev3 steps, 70 000 filterings in one ``identify``)."""
    y = np.array(x, dtype=float, order="C", ndmin=2)
    _compiled_loop()(np.ascontiguousarray(sos, dtype=float), y,
                     np.array(zi, dtype=float, order="C").reshape(len(sos), 1, 2))
    return y[0]


@functools.cache
def _compiled_loop():
    """scipy's compiled second-order-sections loop (a private name), or None."""
    try:
        from scipy.signal._sosfilt import _sosfilt
    except ImportError:
        return None
    return _sosfilt


@functools.cache
def _sos_pass():
    """The one-pass filter :func:`lowpass` runs, chosen at its first call (scipy.signal is
    slow to import): :func:`_core_sos_pass` where scipy's compiled loop is there and answers
    bit for bit as ``sosfilt`` does on a test signal (it is scipy's private name), else
    :func:`_public_sos_pass`."""
    if _compiled_loop() is None:
        return _public_sos_pass
    sos, zi = _design(ORDER, 7.0, 0.01)
    x = np.sin(np.arange(50.0)) + np.arange(50.0)
    try:
        same = np.array_equal(_core_sos_pass(sos, x, zi), _public_sos_pass(sos, x, zi))
    except Exception:  # noqa: BLE001 - any change of a private name: the public one serves
        same = False
    return _core_sos_pass if same else _public_sos_pass


@dataclass
class Kinematics:
    """Filtered position [rad or m], speed [rad/s or m/s], acceleration [rad/s^2 or m/s^2]."""

    theta: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    cutoff_hz: float
    source: str  # 'theta' or 'omega': which measured signal they come from


def kinematics_from_position(theta: np.ndarray, dt: float, cutoff_hz: float) -> Kinematics:
    """Filter the position, then central differences for speed and acceleration."""
    th = lowpass(theta, dt, cutoff_hz)
    om = np.gradient(th, dt)
    return Kinematics(th, om, np.gradient(om, dt), cutoff_hz, "theta")


def kinematics_from_speed(omega: np.ndarray, dt: float, cutoff_hz: float) -> Kinematics:
    """Filter the speed, integrate it for position and differentiate it for acceleration."""
    om = lowpass(omega, dt, cutoff_hz)
    return Kinematics(position_from_speed(om, dt), om, np.gradient(om, dt), cutoff_hz, "omega")


def speed_from_position(theta: np.ndarray, dt: float, cutoff_hz: float | None = None) -> np.ndarray:
    """Speed [rad/s] from angle [rad] (or m/s from m): zero-phase low-pass, central difference."""
    fc = default_cutoff(dt) if cutoff_hz is None else cutoff_hz
    return np.gradient(lowpass(theta, dt, fc), dt)  # as kinematics_from_position's


def position_from_speed(omega: np.ndarray, dt: float) -> np.ndarray:
    """Angle [rad] from speed [rad/s]: cumulative trapezoid, 0 at the first sample."""
    from scipy.integrate import cumulative_trapezoid

    return cumulative_trapezoid(np.asarray(omega, dtype=float), dx=dt, initial=0.0)


def log_kinematics(log, cutoff_hz: float | None = None) -> Kinematics:
    """Filtered position, speed and acceleration of a log, from its measured angle if it has one
    (the better source: an encoder's angle is nearly noise-free), else from its speed.

    Raises :class:`LogError` when the log has neither.
    """
    derived = getattr(log, "derived", set())
    fc = cutoff_hz if cutoff_hz is not None else log_cutoff(log)
    check_cutoff(fc, log.dt, log.path)
    if log.has("theta") and "theta" not in derived:
        return kinematics_from_position(log["theta"], log.dt, fc)
    if log.has("omega") and "omega" not in derived:
        return kinematics_from_speed(log["omega"], log.dt, fc)
    log.require("theta", purpose="speed and acceleration (map an angle or a speed column)")
    raise AssertionError("unreachable")  # pragma: no cover


def log_cutoff(log) -> float:
    """The cut-off [Hz] the log was read with (``--cutoff``), else :func:`default_cutoff`."""
    fc = getattr(log, "cutoff_hz", None)
    return default_cutoff(log.dt) if fc is None else fc


def speed_cutoff(log) -> float | None:
    """The cut-off [Hz] of the filter that derived the log's speed from its angle (an encoder),
    None where the log measures its speed by a sensor of its own."""
    if log.has("omega") and "omega" in getattr(log, "derived", set()) and log.has("theta"):
        return log_cutoff(log)
    return None


def derive_missing(log, cutoff_hz: float | None = None) -> set[str]:
    """Add ``omega`` from ``theta`` or ``theta`` from ``omega`` when one is missing (in place).

    Returns (and adds to ``log.derived``) the names of the derived columns.
    """
    new: set[str] = set()
    if log.has("theta") and not log.has("omega"):
        fc = check_cutoff(cutoff_hz if cutoff_hz is not None else default_cutoff(log.dt),
                          log.dt, log.path)
        log.data["omega"] = speed_from_position(log["theta"], log.dt, fc)
        new.add("omega")
    elif log.has("omega") and not log.has("theta"):
        log.data["theta"] = position_from_speed(log["omega"], log.dt)
        new.add("theta")
    log.derived = set(getattr(log, "derived", set())) | new
    return new
