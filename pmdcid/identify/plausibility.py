"""The plausibility gate: before a stage writes a model, the logs' units are checked against each
other and against what any motor can do. A unit mistake found here is refused with one line
saying what to map (unless ``--force``): a model known to be wrong is never written, not even
with a warning.

Rules (each names the cause and the mapping that fixes it):

- **time unit**: a sample period of 0.2 s or more. A motor identification log is sampled at tens
  of hertz at the very least (the mechanical time constant of a motor is milliseconds to
  seconds); a period of 1 is a 1 kHz log written in ms, 1000 one written in µs.
- what :func:`pmdcid.io.checks.check_log` found on reading: a **saturated sensor** (current or
  speed flat at its extreme for many samples) and a **speed that is not the angle's derivative**
  (rpm, deg/s, rev/s, or time in ms: the ratio names which).
- **no-load speed** (voltage logs, km known): a permanent-magnet motor's speed stays below
  |v|/km, the speed at which the back-EMF km*omega equals the supply. A measured speed several
  times that (median over the driven samples) is in rpm (x 9.55) or deg/s (x 57.3).
- **back-EMF balance** (voltage logs with current, R and km known): km*omega equals the
  back-EMF v - R*i the armature leaves. More than 3 times it (median over the driven samples)
  names rpm or deg/s. Less is allowed (a driver's voltage drop lowers the real v), but not
  30 times less where the rotor turns at half its top speed or more, nor a back-EMF that grows
  over 3 times as fast as km*omega along the logged speeds (a drop is an intercept, not a
  slope): v in mV, or the wrong km.
- **time constants** of the fitted result: an armature L/R above 1 s or a mechanical time
  constant above 100 s is beyond any motor; the time column is in ms or µs. A mechanical time
  constant under 0.5 ms that the logs resolve (over 3 samples) is below any motor's: the time
  column was scaled too small (seconds mapped as ms).
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.errors import LogError, warn
from pmdcid.io.derive import noise_std

#: longest sample period of a motor log [s]
MAX_SAMPLE_PERIOD = 0.2
#: largest armature time constant L/R of any motor [s], largest mechanical one [s]
MAX_TAU_ELECTRICAL = 1.0
MAX_TAU_MECHANICAL = 100.0
#: shortest mechanical time constant of any motor [s]: the smallest coreless motors take a few
#: milliseconds
MIN_TAU_MECHANICAL = 5e-4
#: a time constant this many sample periods long is resolved by a log
RESOLVED_SAMPLES = 3
#: km*omega and the back-EMF v - R*i differ by more than this factor: a unit is wrong
MAX_EMF_FACTOR = 3.0
#: the back-EMF v - R*i at most this many times km*omega where the rotor turns at half its top
#: speed or more (a driver that loses 97 % of its command there drives no motor fast)
MAX_DROP_FACTOR = 30.0
#: median of km*|omega|/|v| over the driven samples above which omega cannot be rad/s
MAX_BACK_EMF_RATIO = 2.0


#: (largest sample period in the unit, its name, symbol, the factor as -c writes it, factor):
#: the first unit whose row takes the period is named (ns: time stamps since 1970 in ns)
TIME_UNITS = ((50.0, "milliseconds", "ms", "ms", 1e-3),
              (2e4, "microseconds", "us", "us", 1e-6),
              (2e8, "nanoseconds", "ns", "1e-9", 1e-9))


def _time_unit_hint(dt: float, path: str = "") -> str:
    """What the time looks like, and the fix: ``-c t=COLUMN*UNIT`` for a table (CSV, Parquet,
    .mat); for a series file (``path``: TDMS, MDF, MCAP, wpilog), whose signals carry their own
    time stamps and refuse ``-c t=``, what its format lets a user do instead."""
    from pmdcid.io.formats import extension, own_time_fix

    fix = own_time_fix(path)
    hit = next((u for u in TIME_UNITS if dt < u[0]), None)
    if hit is None:  # no unit makes this a motor log's period
        where = (f"the time stamps the {extension(path)} file holds" if fix else
                 "the time column (its unit, or another column mapped to t with -c t=COLUMN)")
        return f"the sample period {dt:.3g} s is no motor log's: check {where}"
    _, name, symbol, written, factor = hit
    said = (f"t looks like {name} (a sample period of {dt:g}; {symbol} would make it "
            f"{dt * factor:g} s)")
    if fix:
        fix = fix.format(unit=symbol)
        return f"{said}, and a {extension(path)} file carries its own time: {fix}"
    return f"{said}: map it with -c t=COLUMN*{written}"


def time_unit_issue(log) -> str | None:
    """The time-unit rule: a sample period of :data:`MAX_SAMPLE_PERIOD` or more (None: none)."""
    return _time_unit_hint(log.dt, str(log.path)) if log.dt >= MAX_SAMPLE_PERIOD else None


def log_issues(log) -> list[str]:
    """What is implausible about one log, one message each (empty: nothing)."""
    out = [m for m in (time_unit_issue(log),) if m]
    out += list(getattr(log, "issues", []))
    return out


def _omega_hint(ratio: float) -> str:
    hints = ((60 / (2 * math.pi), "omega looks like rpm: map it with -c omega=COLUMN*rpm"),
             (180 / math.pi, "omega looks like deg/s: map it with -c omega=COLUMN*deg"))
    return next((h for k, h in hints if 0.6 * k < ratio < 1.4 * k),
                "check omega's unit, and km (SI: N m/A = V s/rad)")


def speed_issue(log, km: float | None, R: float | None = None) -> str | None:
    """The no-load-speed and back-EMF rules on a voltage log with a measured speed (None: the
    speed is plausible, or the rules do not apply)."""
    if km is None or not (km > 0) or log.drive != "v" or "omega" not in log.data \
            or "omega" in log.derived:
        return None
    v, om = log["v"], log["omega"]
    vmax = float(np.max(np.abs(v)))
    driven = np.abs(v) > 0.3 * vmax if vmax > 0 else np.zeros(len(v), bool)
    if driven.sum() < 10:
        return None
    ratio = float(np.median(km * np.abs(om[driven]) / np.abs(v[driven])))
    if ratio > MAX_BACK_EMF_RATIO:
        return (f"the speed is {ratio:.3g} x the no-load speed |v|/km allows (km = {km:g} N m/A;"
                f" the back-EMF km*omega cannot exceed the supply): {_omega_hint(ratio)}")
    if R is None or not (R > 0) or "i" not in log.data or "i" in log.derived:
        return None
    emf = v - R * log["i"]  # the back-EMF the armature balance leaves (inductance: transients)
    sure = driven & (np.abs(emf) > 0.02 * vmax)
    if sure.sum() < 100:
        return None
    k = float(np.median(km * om[sure] / emf[sure]))
    if k > MAX_EMF_FACTOR:
        return (f"km*omega is {k:.3g} x the back-EMF v - R*i (R = {R:g} ohm, km = {km:g} N m/A), "
                f"where it should equal it: {_omega_hint(k)}")
    fast = sure & (np.abs(om) > max(0.5 * float(np.max(np.abs(om[sure]))),
                                    MOVES_NOISE * noise_std(om)))
    return _emf_excess_issue(km * om[fast], emf[fast], R, km) if fast.sum() >= 100 else None


def _emf_excess_issue(kw: np.ndarray, emf: np.ndarray, R: float, km: float) -> str | None:
    """The back-EMF v - R*i [V] many times km*omega [V] where the rotor turns at half its top
    speed or more: a driver drops part of its command, but not nearly all of it where the
    rotor turns fast, and a drop is an intercept, not a slope along the speeds. v in mV, or a
    km that is not this motor's."""
    q = float(np.median(emf / kw))
    slope = np.polyfit(kw, emf, 1)[0] if np.ptp(kw) > 0.2 * np.max(np.abs(kw)) else 0.0
    if q > MAX_DROP_FACTOR:
        what = f"is {q:.3g} x km*omega where the rotor turns fast"
    elif slope > MAX_EMF_FACTOR and np.corrcoef(kw, emf)[0, 1] > 0.9:
        what = f"grows {slope:.3g} x as fast as km*omega along the logged speeds"
    else:
        return None
    return (f"the back-EMF v - R*i {what} (R = {R:g} ohm, km = {km:g} N m/A), where it should "
            "equal it: check v's unit and scale (a v in mV: -c v=COLUMN*1e-3) and km")


#: full scales of integer PWM/DAC counts (8 to 16 bits, signed and unsigned)
COUNT_FULL_SCALES = (255, 511, 1023, 2047, 4095, 8191, 16383, 32767, 65535)


def counts_issue(log) -> str | None:
    """A voltage column that holds raw PWM or DAC counts (every value an integer, the largest
    a full scale of :data:`COUNT_FULL_SCALES`): the mapping forgot the scale to volts."""
    if log.drive != "v" or "v" in log.derived:
        return None
    v = np.asarray(log["v"], float)
    v = v[np.isfinite(v)]
    top = float(np.max(np.abs(v))) if v.size else 0.0
    if top not in COUNT_FULL_SCALES or not np.all(v == np.round(v)):
        return None
    return (f"v holds whole numbers up to {top:.0f}, the full scale of raw PWM counts, not "
            f"volts: map it with the scale, e.g. -c v=COLUMN*12/{top:.0f} for a 12 V supply")


def gate(logs, force: bool = False, km: float | None = None, R: float | None = None) -> None:
    """Refuse (:class:`LogError` naming the log) what :func:`log_issues`, :func:`speed_issue` or
    :func:`counts_issue` find, unless ``force``: then each is a warning."""
    for log in logs:
        found = log_issues(log)
        found += [s for s in (speed_issue(log, km, R), counts_issue(log)) if s]
        for msg in found:
            if not force:
                raise LogError(f"{msg} (or --force to fit anyway)", log.path)
            warn(msg, log.path)


def _val(model, name: str) -> float:
    p = model.parameters.get(name)
    return p.value if p is not None else math.nan


def mechanical_tau(model, speed: float = 0.0) -> float:
    """The model's mechanical time constant J/(b + km^2/R + 2 bq speed) [s] at ``speed``
    [rad/s] (per volt: J/(bv + 2 bq speed)); the quadratic drag's part only where the model has
    it (it can hold the speed alone, bv near 0 beside it). NaN without J or damping."""
    R, km, J = _val(model, "R"), _val(model, "km"), _val(model, "J")
    b = _val(model, "bv") if math.isfinite(_val(model, "bv")) else _val(model, "b")
    damping = (b if math.isfinite(b) else 0.0) + (km * km / R if R > 0 and km > 0 else 0.0)
    bq = _val(model, "bq") if "quadratic_drag" in model.effects else math.nan
    if bq > 0 and speed > 0:
        damping += 2.0 * bq * speed
    return J / damping if damping > 0 else math.nan


def typical_speed(logs) -> float:
    """The logs' typical moving speed [rad/s]: the 90th percentile of |omega| (0 without)."""
    w = [np.abs(np.asarray(lg["omega"], float)) for lg in logs if lg.has("omega")]
    w = np.concatenate(w) if w else np.zeros(0)
    w = w[np.isfinite(w)]
    return float(np.quantile(w, 0.9)) if w.size else 0.0


#: a fitted time constant longer than this many times the longest log was not determined by
#: the logs (whatever the unit of t, the ratio is the same): a fit that diverged, not a unit
UNDETERMINED_DURATIONS = 3.0


def _tau_messages(model, speed: float = 0.0) -> list[tuple[str, float]]:
    R, L = _val(model, "R"), _val(model, "L")
    msgs = []
    if R > 0 and L / R > MAX_TAU_ELECTRICAL:
        msgs.append((f"the fitted armature time constant L/R = {L / R:.3g} s is beyond any "
                     "motor's (< 1 s)", L / R))
    tau = mechanical_tau(model, speed)
    if tau > MAX_TAU_MECHANICAL:
        msgs.append((f"the fitted mechanical time constant J/(b+km^2/R) = {tau:.3g} s is "
                     "beyond any motor's (< 100 s)", tau))
    return msgs


#: steady speed per volt [rad/s/V] above which omega is taken for rpm or deg/s: KV 9550 rpm/V,
#: beyond all but the smallest coreless motors (a 7 mm drone motor reaches ~1400: --force)
MAX_SPEED_PER_VOLT = 1000.0


def steady_speed_per_volt(model, vmax: float) -> float:
    """A per-volt model's steady speed per volt above its breakaway [rad/s/V]: the speed where
    its friction (bv omega, Coulomb, and the effects' sliding friction: quadratic drag, Stribeck,
    asymmetry, the friction curve) meets the largest input ``vmax`` [V] less the dead zone,
    over that input less the friction at rest. Without effects exactly 1/bv; a quadratic drag
    that holds the speed down lowers it (diagnose may fit bv near 0 beside it); inf when no
    speed balances the input."""
    from pmdcid.simulate import param_values, param_vector
    from pmdcid.simulate.terms import sliding_friction

    bv = _val(model, "bv") if math.isfinite(_val(model, "bv")) else _val(model, "b")
    if not (math.isfinite(vmax) and vmax > 0) or not model.effects:
        return 1.0 / bv
    p = param_vector(param_values(model, True))
    drive = vmax - max(_val(model, "dz"), 0.0) if model.has("dz") else vmax

    def excess(w: float) -> float:  # friction less the drive at speed w
        return bv * w + sliding_friction(p, w, 1.0) - drive

    lo, hi = 0.0, max(drive / bv, 1.0)
    if excess(0.0) >= 0:
        return 1.0 / bv
    for _ in range(200):  # bracket, then bisect
        if excess(hi) >= 0:
            break
        hi *= 2.0
    else:
        return math.inf
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(mid) < 0 else (lo, mid)
    return hi / -excess(0.0)


def lumped_issues(model, logs) -> list[str]:
    """Per-volt parameters no motor has (a lumped model: voltage and speed logs), each with the
    mapping mistake that makes them: a Coulomb friction or dead zone at or beyond the largest
    input (the rotor could never have turned: v is not in volts, or the fit did not converge),
    a steady speed per volt 1/bv' beyond any motor's (omega in rpm or deg/s)."""
    vmax = max((float(np.nanmax(np.abs(lg["v"]))) for lg in logs if lg.drive == "v"),
               default=math.nan)
    out = []
    for name, what in (("bc", "Coulomb friction"), ("dz", "dead zone")):
        x = _val(model, name)
        if vmax > 0 and x >= vmax:
            out.append(f"the {what} per volt {name} = {x:.3g} V is at or beyond the largest "
                       f"input ({vmax:.3g} V), yet the rotor turned: check v's unit and scale "
                       "(-c v=COLUMN*SCALE: a duty or PWM count needs the supply voltage, e.g. "
                       "-c v=pwm*12/255) and the speed's sign against v (-c omega=COLUMN*-1)")
    bv = _val(model, "bv") if math.isfinite(_val(model, "bv")) else _val(model, "b")
    rate = steady_speed_per_volt(model, vmax) if bv > 0 else math.nan
    if rate > MAX_SPEED_PER_VOLT:
        out.append(f"the steady speed per volt 1/bv = {rate:.4g} rad/s/V is beyond any "
                   f"brushed motor's (< {MAX_SPEED_PER_VOLT:g}; a micro coreless motor may "
                   "reach 1400: --force): omega is likely in rpm (x 9.55) or deg/s (x 57.3), "
                   "not rad/s: map it with -c omega=COLUMN*rpm (or *deg)")
    return out


#: a measured signal "moves" when it leaves its start by this many noise std (its rest at the
#: start: its first samples within a fifth of that)
MOVES_NOISE = 20.0


def turns_from_rest(log) -> bool:
    """The rotor is at rest at the log's start and turns later (measured speed, else angle):
    then some input torque overcame the friction at rest."""
    sig = next((c for c in ("omega", "theta") if log.has(c) and c not in log.derived), None)
    if sig is None:
        return False
    x = np.asarray(log[sig], float)
    x = x[np.isfinite(x)]
    head = max(5, x.size // 50)
    if x.size < 2 * head:
        return False
    noise = noise_std(x)
    start = np.median(x[:head])
    rest = (abs(start) if sig == "omega" else float(np.ptp(x[:head]))) < MOVES_NOISE / 5 * noise
    return bool(noise > 0 and rest and np.max(np.abs(x - (0.0 if sig == "omega" else start)))
                > MOVES_NOISE * noise)


def drive_torque(model, log) -> float:
    """The largest torque ``log``'s input applies [N m] (per volt: [V] for a lumped model): |tau|,
    or the stall torque km |v| / R, plus the model's constant load torque |tau0| (gravity on an
    axis can turn it too); NaN when the model cannot say."""
    u = np.asarray(log.u, float)
    u = u[np.isfinite(u)]
    top = float(np.max(np.abs(u))) if u.size else math.nan
    if log.drive != "tau" and not model.extra.get("lumped"):
        km, R = _val(model, "km"), _val(model, "R")
        top = km * top / R if km > 0 and R > 0 else math.nan
    load = abs(_val(model, "tau0")) if "torque_offset" in model.effects else 0.0
    return top + (load if math.isfinite(load) else 0.0)


def stuck_issue(model, logs) -> str | None:
    """A model whose friction at rest (Coulomb bc, or the dead zone dz) is at or beyond the
    largest torque a log's input applies, while that log's rotor turns from rest: the model
    holds the rotor still where the log shows it turning (None: no such log)."""
    unit = "V per volt" if model.extra.get("lumped") else "N m"
    for log in logs:
        if not turns_from_rest(log):
            continue
        top = drive_torque(model, log)
        for name, what in (("bc", "Coulomb friction"), ("dz", "dead zone")):
            x = _val(model, name)
            if top > 0 and x >= top:
                return (f"the fitted {what} {name} = {x:.3g} {unit} is at or beyond the largest "
                        f"torque the input of {log.path} applies ({top:.3g} {unit}), yet its "
                        "rotor turns from rest: the model never moves there. Check the units "
                        "and scale of the input and the speed (and the speed's sign against the "
                        "input), or give logs that agree (a log whose rotor stays still at an "
                        "input that turns it in another)")
    return None


def out_of_bounds(model) -> str | None:
    """The first parameter outside its physical bounds, or an effect torque beyond the motor's
    (the checks the model file's writer applies), in words (None: all within)."""
    from pmdcid.errors import ModelError
    from pmdcid.model.effects.torque_limit import check_plausible
    from pmdcid.model.params import check_bounds

    try:
        for name, par in model.parameters.items():
            check_bounds(name, par.value, None)
        check_plausible({k: p.value for k, p in model.parameters.items()}, None,
                        model.extra.get("lumped") is True)
    except ModelError as exc:
        return str(exc)
    return None


def range_issue(model) -> str | None:
    """:func:`out_of_bounds` of a fitted model, as a line about the logs (None: all within)."""
    bad = out_of_bounds(model)
    if bad is None:
        return None
    return (f"the fit gives {bad}: the logs do not behave as this motor model's (check the "
            "units, signs and offsets of the input and speed columns, or the rotor was "
            "blocked); the model was not written")


def gate_result(model, logs, force: bool = False) -> None:
    """The rules on a fitted model before it is written: for a lumped model the per-volt rules
    (:func:`lumped_issues`); the time constants (:func:`_tau_gate`: they name a time unit, so
    they speak first); a value outside its physical bounds (:func:`range_issue`, never
    forced: the model file cannot hold it); friction that holds the rotor still where a log
    turns (:func:`stuck_issue`)."""
    path = logs[0].path if logs else None
    if model.extra.get("lumped"):
        for msg in lumped_issues(model, logs):
            _refuse(msg, path, force)
    _tau_gate(model, logs, force)
    bad = range_issue(model)
    if bad:
        raise LogError(bad, ", ".join(dict.fromkeys(lg.path for lg in logs)) or None)
    stuck = None if model.extra.get("lumped") else stuck_issue(model, logs)
    if stuck:
        _refuse(stuck, path, force)


def _refuse(msg: str, path, force: bool) -> None:
    if not force:
        raise LogError(f"{msg} (or --force to write it anyway)", path)
    warn(msg, path)


def _fast_tau_message(model, logs) -> str | None:
    """A mechanical time constant shorter than any motor's that the logs resolve (several
    samples long): the time column scaled too small (a log in s mapped as ms)."""
    if not logs:
        return None
    tau = mechanical_tau(model, typical_speed(logs))
    dt = min(log.dt for log in logs)
    if not RESOLVED_SAMPLES * dt < tau < MIN_TAU_MECHANICAL:
        return None
    return (f"the fitted mechanical time constant {tau:.3g} s, {tau / dt:.0f} samples of "
            f"{dt:.3g} s, is shorter than any motor's ({1e3 * MIN_TAU_MECHANICAL:g} ms): t is "
            "scaled too small (t in seconds needs no -c t=COLUMN*ms)")


def _tau_gate(model, logs, force: bool) -> None:
    """A time constant beyond any motor's that the logs resolve (within a few log lengths)
    names the time unit; one far longer than every log was not determined by them (a fit that
    diverged), and says so."""
    msgs = _tau_messages(model, typical_speed(logs))
    if not msgs:
        fast = _fast_tau_message(model, logs)
        if fast:
            _refuse(fast, logs[0].path, force)
        return
    text, tau = msgs[0]
    dt = max(log.dt for log in logs)
    longest = max(float(log.t[-1] - log.t[0]) for log in logs) if logs else math.inf
    if tau > UNDETERMINED_DURATIONS * longest:
        msg = (f"{text}, and {tau / longest:.3g} times the longest log ({longest:.3g} s): the "
               "logs do not determine it (the fit diverged, or the speed never settles); "
               "record steps held until the speed settles")
    else:
        msg = f"{text}: is t in ms or us? (sample period {dt:g} s; map it with -c t=COLUMN*ms)"
    _refuse(msg, logs[0].path if logs else None, force)
