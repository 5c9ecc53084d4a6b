"""Plausibility checks on a freshly read log: suspicious but usable data gives a warning.

- :func:`check_saturation`: a measured signal (current [A], speed [rad/s]) that sits flat at its
  extreme value for many samples, entered with a finite slope, looks clipped at a sensor or ADC
  rail. Fits on clipped data are biased.
- :func:`check_speed_units`: when a log measures both speed and angle, the speed must equal the
  angle's time derivative. A ratio near 60/(2 pi) says the speed is in rpm, near 180/pi that it is
  in deg/s, and so on: the warning names the likely unit and the mapping that fixes it.
- :func:`check_speed_range`: a measured speed beyond :data:`MAX_SPEED` is no motor's (rad/s,
  or m/s on a linear axis): a column in counts per second, or a scale applied twice.
- :func:`check_input_range`: the same gate on the input and the current: a voltage beyond
  :data:`MAX_VOLTAGE`, a torque (force) beyond :data:`MAX_TORQUE`, a current beyond
  :data:`MAX_CURRENT` is no DC motor's: a raw ADC or PWM column, or a scale applied twice.
- :func:`check_angle_wrap`: a measured angle that jumps back by about a turn in one sample,
  against its motion, is a wrapped angle (0 to 2 pi, 0 to 360 deg, a counter that overflows):
  its derivative, the speed every stage fits, would hold a spike of a turn per sample there.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.errors import warn

#: columns checked for clipping (inputs and angles legitimately sit flat)
SATURATION_COLUMNS = ("i", "omega")
#: a rail must hold at least this fraction of the samples (and 5 samples) ...
SATURATION_MIN_FRACTION = 0.005
#: ... and at least this many times the count of any other single value
SATURATION_PILEUP = 3.0

#: fastest measured speed of any motor [rad/s] (or linear axis [m/s]): 1e6 rad/s is 9.5 million
#: rpm, 20 times the fastest spindles built; the catalogue's speeds (Stribeck ws) end there too
MAX_SPEED = 1e6

#: the largest armature voltage [V], current [A] and torque [N m] (force [N] on a linear axis)
#: of any DC motor, each far beyond the largest built (traction and mill motors: ~3 kV, ~20 kA,
#: ~1e6 N m): only a unit or scale mistake reaches them
MAX_VOLTAGE = 1e5
MAX_CURRENT = 1e5
MAX_TORQUE = 1e7
#: column -> (its largest plausible magnitude, its SI unit, what it is)
INPUT_LIMITS = {"v": (MAX_VOLTAGE, "V", "voltage"), "i": (MAX_CURRENT, "A", "current"),
                "tau": (MAX_TORQUE, "N m", "torque")}

#: speed/angle-derivative ratios that betray a unit, and the mapping that fixes them
UNIT_RATIOS: tuple[tuple[float, str], ...] = (
    (60.0 / (2 * math.pi), "omega looks like rpm: map it with -c omega=COLUMN*rpm"),
    (180.0 / math.pi, "omega looks like deg/s: map it with -c omega=COLUMN*deg"),
    (math.pi / 180.0, "theta looks like degrees: map it with -c theta=COLUMN*deg"),
    (1.0 / (2 * math.pi), "omega looks like rev/s: map it with -c omega=COLUMN*rps"),
    (2 * math.pi, "theta looks like revolutions: map it with -c theta=COLUMN*rev"),
    (1e-3, "theta looks like milli-units (mm, mrad): map it with -c theta=COLUMN*1e-3, or t is "
           "scaled 1000 x too small (a t in s mapped with *ms)"),
    (1e-6, "t is scaled 1e6 x too small (a t in s mapped with *us), or theta is in micro-units"),
    (1e3, "omega looks like milli-units per second (-c omega=COLUMN*1e-3), or t is in ms "
          "(-c t=COLUMN*ms)"),
    (1e6, "t looks like microseconds: map it with -c t=COLUMN*us"),
)


def check_log(log) -> list[str]:
    """Run every plausibility check on a :class:`~pmdcid.io.Log` (measured columns only).

    Returns what looks wrong, one message each, without warning: the caller warns (a command
    that only reads) or refuses (a stage about to write a model, see
    :mod:`pmdcid.identify.plausibility`).
    """
    import warnings

    from pmdcid.errors import PmdcidWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PmdcidWarning)
        for col in SATURATION_COLUMNS:
            if col in log.data and col not in log.derived:
                check_saturation(log.data[col], col, log.path)
        if "omega" in log.data and "omega" not in log.derived:
            check_speed_range(log.data["omega"], log.path)
        for col in INPUT_LIMITS:
            if col in log.data and col not in log.derived:
                check_input_range(log.data[col], col, log.path)
        if "omega" in log.data and "theta" in log.data and not log.derived & {"omega", "theta"}:
            check_speed_units(log.data["omega"], log.data["theta"], log.dt, log.path)
        if "theta" in log.data and "theta" not in log.derived:
            t = log.t_file if log.t_file is not None else log.t
            check_angle_wrap(log.data["theta"], t, log.path)
    prefix = f"{log.path}: "
    return [str(w.message).removeprefix(prefix) for w in caught
            if issubclass(w.category, PmdcidWarning)]


def check_speed_range(omega: np.ndarray, path: str) -> bool:
    """Warn when the measured speed exceeds :data:`MAX_SPEED` anywhere: no motor turns that
    fast (True: warned)."""
    top = _largest(omega)
    if top <= MAX_SPEED:
        return False
    warn(f"omega reaches {top:.3g} rad/s, beyond any motor's speed (< {MAX_SPEED:g} rad/s): "
         "check its unit and scale (-c omega=COLUMN*FACTOR; encoder counts per second need "
         "2*pi/COUNTS_PER_REV)", path)
    return True


def _largest(x: np.ndarray) -> float:
    """The largest finite magnitude in ``x`` (0 when it holds none)."""
    a = np.abs(np.asarray(x, float))
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else 0.0


def check_input_range(x: np.ndarray, name: str, path: str) -> bool:
    """Warn when column ``name`` (``v``, ``i`` or ``tau``) exceeds its :data:`INPUT_LIMITS`
    anywhere: no DC motor's voltage, current or torque is that large (True: warned)."""
    limit, unit, what = INPUT_LIMITS[name]
    top = _largest(x)
    if top <= limit:
        return False
    warn(f"{name} reaches {top:.3g} {unit}, beyond any DC motor's {what} (< {limit:g} {unit}): "
         f"check its unit and scale (-c {name}=COLUMN*FACTOR; raw ADC or PWM counts need the "
         "full scale's value over the counts)", path)
    return True


def _rail(x: np.ndarray, value: float) -> tuple[int, float]:
    """Samples sitting at ``value`` and the largest jump onto a run of them."""
    at = x == value
    count = int(at.sum())
    starts = np.flatnonzero(at[1:] & ~at[:-1]) + 1
    jump = float(np.max(np.abs(x[starts - 1] - value))) if len(starts) else 0.0
    return count, jump


def _dithers(x: np.ndarray, value: float, values: np.ndarray) -> bool:
    """True when ``value`` (the top or bottom of ``x``) is a quantised level the signal settles
    on, not a rail: every run at it is entered from the next level (one quantum away: a
    settled speed logged in whole rpm or encoder counts moves between neighbouring levels), and
    it alternates with that level, at least two runs at it per stretch spent at the two levels.
    A rail is reached with a kink: entered from further below (the signal still rising, more
    than a quantum a sample) or held in one run while the signal would have gone on."""
    nxt = values[1] if value == values[0] else values[-2]  # ``values``: sorted, 20 or more
    at, near = x == value, (x == value) | (x == nxt)
    starts = np.flatnonzero(at[1:] & ~at[:-1]) + 1
    if not len(starts) or not np.all(x[starts - 1] == nxt):
        return False
    stretches = int(np.sum(near[1:] & ~near[:-1])) + int(near[0])
    runs = len(starts) + int(at[0])
    return runs >= 2 * max(stretches, 1)


def check_saturation(x: np.ndarray, name: str, path: str) -> bool:
    """Warn (and return True) when ``x`` looks clipped flat at its maximum or minimum (not a
    quantised level it settles on, :func:`_dithers`)."""
    n = len(x)
    if n < 20:
        return False
    lo, hi = float(np.min(x)), float(np.max(x))
    span = hi - lo
    if not span > 0:
        return False
    values, counts = np.unique(x, return_counts=True)
    if len(values) < 20:  # a coarse (few-level) signal: flat stretches are normal
        return False
    for value, side in ((hi, "maximum"), (lo, "minimum")):
        if value == 0.0:  # at rest is not a rail
            continue
        count, jump = _rail(x, value)
        others = counts[values != value]
        if (count >= max(5, SATURATION_MIN_FRACTION * n)
                and count >= SATURATION_PILEUP * float(others.max())
                and jump > 1e-6 * span and not _dithers(x, value, values)):
            warn(f"column '{name}' sits flat at its {side} {value:.6g} for {count} samples "
                 f"({100.0 * count / n:.1f} %): the sensor looks saturated (clipped); fits will "
                 "be biased: cut those parts or re-record with more sensor range", path)
            return True
    return False


def check_speed_units(omega: np.ndarray, theta: np.ndarray, dt: float, path: str) -> float | None:
    """Compare speed [rad/s] with the angle's [rad] derivative; warn on a unit-like factor.

    Angle increments over windows of ``s`` samples are regressed on the speed integrated over
    the same windows (integration averages speed noise, the window averages encoder steps).
    Returns the ratio speed / (d angle/dt), or None when the log moves too little to tell.
    """
    n = len(omega)
    if n < 20:
        return None
    s = max(1, n // 200)
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (omega[1:] + omega[:-1])) * dt))
    d_om, d_th = cum[s:] - cum[:-s], theta[s:] - theta[:-s]
    if not (np.any(d_th) and np.any(d_om)):
        return None
    with np.errstate(all="ignore"):
        r = np.corrcoef(d_om, d_th)[0, 1]
        k = float(np.dot(d_om, d_th) / np.dot(d_th, d_th))
    if not (np.isfinite(r) and np.isfinite(k)) or abs(r) < 0.9:
        return None
    if 0.8 <= k <= 1.25:
        return k
    if -1.25 <= k <= -0.8:
        warn("omega and d(theta)/dt have opposite signs: one sensor counts the other way "
             "(map it with e.g. -c omega=COLUMN*-1)", path)
        return k
    hint = next((h for ratio, h in UNIT_RATIOS if abs(math.log(abs(k) / ratio)) < 0.1),
                "check the units and scales of both columns")
    warn(f"omega is {k:.4g} x d(theta)/dt, where it should equal it: {hint}", path)
    return k


#: an angle step of at least this much [rad] in one sample (a wrap of 2 pi put on a loop-timed
#: log's grid is split between two steps: one of them keeps more than 2 rad) ...
WRAP_MIN_STEP = 2.0
#: ... and this many times the median step, against the motion around it, is a wrap
WRAP_RATIO = 20.0
#: samples on each side of a step that tell the motion around it
WRAP_WINDOW = 10


def check_angle_wrap(theta: np.ndarray, t: np.ndarray, path: str) -> bool:
    """Warn (True) when the angle ``theta`` [rad] wraps: it steps by :data:`WRAP_MIN_STEP` or
    more in one sample, :data:`WRAP_RATIO` times its median step, against the way it moves in
    the :data:`WRAP_WINDOW` samples around (an angle kept within one turn, or an encoder
    counter that overflows). Its derivative, the speed the stages fit, would hold a spike of
    about a turn per sample at every wrap, and the fits a wrong model."""
    d = np.diff(np.asarray(theta, float))
    if len(d) < 2 * WRAP_WINDOW:
        return False
    a = np.abs(d)
    big = (a >= WRAP_MIN_STEP) & (a > WRAP_RATIO * float(np.median(a)))
    if not big.any():
        return False
    c = np.concatenate(([0.0], np.cumsum(np.where(big, 0.0, d))))
    k = np.flatnonzero(big)
    around = c[np.minimum(k + WRAP_WINDOW + 1, len(d))] - c[np.maximum(k - WRAP_WINDOW, 0)]
    wraps = k[np.sign(d[k]) == -np.sign(around)]
    if not len(wraps):
        return False
    j = int(wraps[0])
    warn(f"theta jumps by {d[j]:.4g} rad in one sample at t = {t[j + 1]:.6g} s against its "
         f"motion ({len(wraps)} time(s)): a wrapped angle (within 2*pi or 360 deg, or a counter "
         "that overflows): log the multi-turn angle or unwrap it (numpy.unwrap)", path)
    return True


#: an input sample this many times the rest's range beyond it (in a run of at most
#: GLITCH_RUN samples) is a logging glitch, not a command
GLITCH_SPANS = 3.0
GLITCH_RUN = 2


def held_glitches(name: str, x: np.ndarray, path: str) -> np.ndarray:
    """The input column ``x`` (``v`` [V] or ``tau`` [N m]) with isolated glitches held at the
    value before them (a warning names them): a run of at most :data:`GLITCH_RUN` samples more
    than :data:`GLITCH_SPANS` times the rest's range (0.5 to 99.5 %) outside that range, where
    the rest varies (a log at rest but for a short kick, an impulse test, is left alone). A
    drive holds each command it is given, so a serial glitch of 100 V in a 0-2 V log would
    otherwise be simulated as a kick, and hide the log's steps."""
    lo, hi = np.percentile(x, [0.5, 99.5])
    span = float(hi - lo)
    if not span > 0:
        return x
    out = (x < lo - GLITCH_SPANS * span) | (x > hi + GLITCH_SPANS * span)
    if not out.any():
        return x
    edges = np.diff(np.concatenate(([0], out.view(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    short = [(a, e) for a, e in zip(starts, ends, strict=True) if e - a <= GLITCH_RUN]
    if not short:
        return x
    y = x.copy()
    for a, e in short:
        y[a:e] = y[a - 1] if a > 0 else y[e] if e < len(y) else y[a]
    a = short[0][0]
    warn(f"column '{name}': {len(short)} isolated glitch(es) far outside its range "
         f"{lo:.4g} to {hi:.4g} (e.g. {x[a]:.4g} at data row {a + 1}) held at the value before "
         "them: a drive holds its command; remove those rows if they were real", path)
    return y
