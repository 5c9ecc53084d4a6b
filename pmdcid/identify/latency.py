"""A constant latency between command and speed, from voltage-and-speed step logs.

On a lumped (per-volt) model there is no electrical lag: the torque follows the command at once,
and a rotor at rest starts as soon as the command exceeds its dead zone and static friction. Any
time between a step of the command and the speed's first move is then latency: the command
applied late by a host-paced loop (USB or serial), or the speed read late (a counting window, a
filter). On voltage and speed alone the two are one thing (docs/effects.md, "Real drives"), which
``sensor_delay`` holds. fit-mechanical's curve fits time a dead time per step, but their dead
time also absorbs the curve's misfit (on exact friction logs without latency it is 0-3 ms), so
the latency is measured with the kernel instead (:func:`step_latency`): the fitted model is
simulated on each step log and delayed by the shift that minimises the squared speed error over
every log together (one FFT correlation per log, refined between samples by a parabola). A shift
of under :data:`MIN_SAMPLES` samples is not kept: the zero-order hold and a speed counted over
the last sample period already offset the speed by half a sample each.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.effects import param_spec

#: a latency shorter than this many sample periods is not kept (see the module docstring)
MIN_SAMPLES = 2


def shift_curve(padded: np.ndarray, meas: np.ndarray, a: int, b: int, kmax: int) -> np.ndarray:
    """Mean squared error of a simulation delayed by k samples against ``meas[a:b]``, for k =
    -kmax..kmax; ``padded`` is the simulation with kmax edge samples added at each end (the
    rotor held its first and last state outside the log). One FFT correlation."""
    from pmdcid.identify.filters import correlate_valid

    seg = padded[a:b + 2 * kmax]
    w = meas[a:b]
    cross = correlate_valid(seg, w)[::-1]  # index k + kmax
    c2 = np.concatenate(([0.0], np.cumsum(seg * seg)))
    width = b - a
    starts = np.arange(2 * kmax, -1, -1)  # delay k reads seg[kmax - k : kmax - k + width]
    ss = c2[starts + width] - c2[starts]
    return (ss - 2.0 * cross + float(np.dot(w, w))) / width


def parabola_min(curve: np.ndarray, j: int) -> float:
    """The minimum's position between samples: a parabola through curve[j-1..j+1] [index]."""
    if j <= 0 or j >= len(curve) - 1:
        return float(j)
    a, b, c = curve[j - 1], curve[j], curve[j + 1]
    den = a - 2.0 * b + c
    return float(j) + (0.5 * (a - c) / den if den > 0 else 0.0)


def speed_logged(log) -> bool:
    """Whether the log measures the speed, by a sensor of its own or as the derivative of its
    angle (an encoder)."""
    return log.has("omega") and ("omega" not in log.derived or log.has("theta"))


def measured_speed(log, sim) -> np.ndarray:
    """The simulation ``sim``'s speed [rad/s] as the log measures it: its own, or where the
    log's speed is derived from its angle, the simulated angle's speed derived by the same
    filter (a zero-phase filter spreads every step's start over its length both ways)."""
    from pmdcid.io.derive import speed_cutoff, speed_from_position

    fc = speed_cutoff(log)
    return sim.omega if fc is None else speed_from_position(sim.theta, log.dt, fc)


def _shift_totals(use, model, kmax) -> tuple[np.ndarray, int]:
    """Summed squared speed error of ``model`` on the logs ``use`` for each shift -kmax..kmax."""
    from pmdcid.simulate import input_is_torque, param_values, simulate_values
    from pmdcid.simulate.initial import initial_state

    total, nsamp = np.zeros(2 * kmax + 1), 0
    for lg in use:
        torque = input_is_torque(lg, model)
        vals = param_values(model, torque)
        sim = measured_speed(lg, simulate_values(lg.t, lg.u, vals, torque,
                                                 x0=initial_state(lg),
                                                 within=lg.input_within()))
        meas = np.asarray(lg["omega"], float)
        if not (np.isfinite(sim).all() and np.isfinite(meas).all()):
            continue
        total += lg.n * shift_curve(np.pad(sim, kmax, mode="edge"), meas, 0, lg.n, kmax)
        nsamp += lg.n
    return total, nsamp


def step_latency(logs, model) -> tuple[float, float] | None:
    """(latency [s], its white-noise standard error [s]) of the measured speed behind
    ``model`` simulated on ``logs`` (module docstring), including a ``sensor_delay`` the model
    already has; None when it is under :data:`MIN_SAMPLES` samples or no log measures a speed."""
    use = [lg for lg in logs if speed_logged(lg) and lg.n > 20]
    if not use:
        return None
    dt = use[0].dt
    use = [lg for lg in use if abs(lg.dt - dt) <= 1e-6 * dt]
    base = 0.0
    if "sensor_delay" in model.effects and "delay" in model.parameters:
        base = float(model.parameters["delay"].value)
    kmax = max(2, min(lg.n for lg in use) // 50)
    total, nsamp = _shift_totals(use, model, kmax)
    if nsamp == 0:
        return None
    j = int(np.argmin(total))
    k = parabola_min(total, j) - kmax
    latency = base + k * dt
    if latency < MIN_SAMPLES * dt:
        return None
    curv = (total[j - 1] - 2 * total[j] + total[j + 1]) if 0 < j < len(total) - 1 else 0.0
    sigma2 = float(total[j]) / max(nsamp - 1, 1)
    se = math.sqrt(2.0 * sigma2 / curv) * dt if curv > 0 else math.nan
    return latency, se


#: the lag is kept when its estimate exceeds this many standard errors, and a latency only when
#: it exceeds :data:`MIN_SAMPLES` sample periods
LAG_SIGMAS = 3.0


def step_lag(logs, model) -> dict | None:
    """A lumped model's electrical time constant and latency from its step logs, fitted
    together: ``{"tau_e": (value, se), "delay": (value, se), "J": (value, se)}`` [s, s,
    V s^2/rad] (a key left out when not found), or None when no log measures a speed.

    The steps' curve fits fold an electrical lag into their dead time and J. Here the model
    with the steps' bv and bc is simulated on the step logs (per volt, the kernel's voltage
    structure, :func:`pmdcid.model.lumped.kernel_values`) with J, bv, bc, tau_e and a sensor
    delay free, from two starts (all the steps' dead time as lag, or all as latency), the
    better kept; then with the dead zone and the back-EMF share free too from the lag's start
    and from that fit where it resolved a lag (:func:`_dead_zone_fit`: a dead zone above the
    running friction pins the lagged torque), the lowest BIC kept. A lag rounds the start of
    each step, a latency moves it whole: where the sampling resolves the lag, the speed error
    tells them apart. tau_e is kept when it exceeds :data:`LAG_SIGMAS` standard errors, the
    delay when it exceeds :data:`MIN_SAMPLES` samples; when both are found, the latency alone
    is kept (``lag_and_latency`` says what was found).
    """
    from pmdcid.simulate import logs_for

    use = [lg for lg in logs if speed_logged(lg) and lg.n > 20]
    if not use or not (model.has("J") and model.has("bv")):
        return None
    dt = use[0].dt
    use = logs_for([lg for lg in use if abs(lg.dt - dt) <= 1e-6 * dt], model)
    shift = step_latency(use, model)
    d0 = max(shift[0] if shift else 0.0, dt)
    base = {"J": model.value("J"), "bv": model.value("bv"),
            "bc": max(model.value("bc") if model.has("bc") else 0.0, 1e-6)}
    fits = [f for f in (_lag_fit(use, model, {**base, "tau_e": tau, "delay": delay})
                        for tau, delay in ((d0, 0.05 * dt), (0.05 * dt, d0))) if f is not None]
    if not fits:
        return None
    both = min(fits, key=lambda f: f.stats.chisqr)
    starts = [{**base, "tau_e": d0, "delay": 0.05 * dt}]
    if _z(both.estimates["tau_e"]) > LAG_SIGMAS:  # its lag and latency as it split them
        starts.append({k: e.value for k, e in both.estimates.items()})
    pinned = [f for f in (_dead_zone_fit(use, model, s) for s in starts) if f is not None]
    both = min([both, *pinned], key=lambda f: f.stats.bic)
    least = max(0.05 * dt, shortest_lag(use))
    return (shift and _lag_alone(use, model, both, least)) or _found(use, model, both, dt,
                                                                      shift, least)


def shortest_lag(logs) -> float:
    """The shortest electrical lag [s] the logs' speeds can show as a lag: 0 where every log
    measures its speed; where one derives it from its angle, 1/(2 pi fc) of the lowest
    cut-off fc of the zero-phase filters that derived it. The filter keeps nothing above fc,
    and below its corner 1/(2 pi tau) a lag differs from the inertia it folds into (J' +
    tau_e (bv' - ke), per volt) only by terms of (2 pi f tau)^2. On clean samples a shorter
    lag is often resolved, but where something else delays the derived speed's start (an
    encoder's first count after gear play, loop-timed rows interpolated onto a grid) a lag
    fitted through the filter stands in for it with as sure a standard error and as low a
    chi-square: nothing the steps hold tells them apart (docs/identification.md, "Session
    32"), so a shorter lag is not kept."""
    from pmdcid.io.derive import speed_cutoff

    cut = [fc for fc in map(speed_cutoff, logs) if fc is not None]
    return 1.0 / (2.0 * math.pi * min(cut)) if cut else 0.0


def _lag_alone(use, model, both, least) -> dict | None:
    """The lag alone (:func:`step_lag`'s return) where the joint fit ``both`` split the
    steps' dead time into a lag and a latency that it resolves neither of: the fit with the
    latency held at 0 from their sum, kept when it resolves its lag and has the lower BIC.
    None otherwise (then :func:`_found` judges ``both``); ``least``: the shortest lag [s]
    kept (:func:`shortest_lag`, at least a twentieth of a sample). Asked only where the
    kernel's shift found a latency, which :func:`_found` would otherwise write: where it
    found none, an unresolved lag stays a bound (guanlunlu-l298n: the lag alone resolved at
    3.2 +- 0.2 ms, BIC 7 below the pair, but the joint fit with it then read the back-EMF
    share as 0.5 +- 0.3 and the dead zone as 4.7 V, and the held-out 6 V steps went 0.024 ->
    0.42).

    A lag and a latency both round or move a step's start: where the two are not resolved
    apart the joint fit stops anywhere along their ridge (with the sliding dead-zone edge tried
    in session 17, docs/model.md: the large motor's seed 3 at 500 Hz,
    L/R 2 ms: 1.0 +- 0.4 ms of lag and 0.95 +- 0.4 ms of latency, chi-square 6241; the lag
    alone 1.95 +- 0.05 ms, 6240), and neither passing its test left the whole dead time to a
    latency (4.1 ms). Every armature has its L/R; a latency needs its own evidence."""
    est = both.estimates
    te, d = est["tau_e"], est["delay"]
    dt = use[0].dt
    if _z(te) > LAG_SIGMAS or _z(d) > LAG_SIGMAS or d.value >= MIN_SAMPLES * dt:
        return None
    v = {k: e.value for k, e in est.items()}
    lone = _lag_fit(use, model, {**v, "tau_e": te.value + d.value, "delay": 0.0},
                    hold="delay", extra=tuple(k for k in PINNED if k in v))
    if lone is None or lone.stats.bic >= both.stats.bic:
        return None
    j, tau = lone.estimates["J"], lone.estimates["tau_e"]
    if _z(tau) <= LAG_SIGMAS or tau.value < least:
        return None
    return {"J": (j.value, j.stderr), "tau_e": (tau.value, tau.stderr)}


#: the back-EMF's share of the per-volt damping the dead-zone fit starts from (a motor's
#: mechanical viscous friction is a small part of its per-volt damping: 0.4 % on a motor whose
#: viscous loss is 0.4 % of its stall torque at no-load speed)
PINNED_SHARE = 0.99


def _dead_zone_fit(use, model, start: dict):
    """The steps' lag fit with the dead zone and the back-EMF share free too, from ``start``
    with the steps' offset (its bc) as the dead zone and the share at :data:`PINNED_SHARE`;
    None where the fit fails. :func:`step_lag` runs it from all the dead time as lag and,
    where the better fit without them resolved a lag, from that fit too (a lag and a latency
    split as it found them), and keeps the lowest BIC (the two parameters' cost paid). Not
    from a fit that found no lag: the lag first (from there, on the large motor's seed 2 at
    500 Hz, the dead-zone fit stops at a 2.1 ms latency and no lag, L/R 2 ms).

    Per volt the dead zone acts on the lagged torque v - ke w (:mod:`pmdcid.model.lumped`).
    Where the friction a running rotor needs is below the dead zone, the torque is pinned at
    its edge: every steady speed is (v - dz)/ke, so the steps' offset is the dead zone, not
    the Coulomb friction, and each change of level drives the rotor with the torque beyond the
    dead zone less the friction. Without the dead zone the lag fit cannot draw that: it reads
    the steps' starts as a latency (hobby and large motors, friction 2-3 % of the stall torque:
    a sensor delay of 3.3 ms in place of L/R 2 ms, chi-square 10 x the truth's)."""
    return _lag_fit(use, model, {**start, "dz": start["bc"], "ke_share": PINNED_SHARE},
                    extra=("dz", "ke_share"))


def _z(est) -> float:
    """An estimate's size in its standard errors (0 where the error is not finite)."""
    return est.value / est.stderr if est.stderr > 0 and math.isfinite(est.stderr) else 0.0


def _found(use, model, both, dt, shift, least) -> dict:
    """What the steps' joint fit ``both`` determines (:func:`step_lag`'s return; ``least``:
    the shortest lag kept, :func:`_lag_alone`'s). A lag shorter than the derived speed's filter
    shows is ``tau_e_filter``, that limit [s], and not kept."""
    best = both.estimates
    te, d = best["tau_e"], best["delay"]
    out = {"J": (best["J"].value, best["J"].stderr)}
    if _z(te) > LAG_SIGMAS and te.value > 0.05 * dt:
        if te.value < least:
            out["tau_e_filter"] = least
        else:
            out["tau_e"] = (te.value, te.stderr)
    elif math.isfinite(te.stderr):  # not resolved: a bound, said in words
        out["tau_e_bound"] = profile_bound(use, model, both, te.value + 2.0 * te.stderr, dt)
        if out["tau_e_bound"] >= lag_ceiling({k: e.value for k, e in best.items()}):
            out["tau_e_ceiling"] = True  # the steps do not bound it below their mechanics
    if d.value >= MIN_SAMPLES * dt or _z(d) > LAG_SIGMAS:
        out["delay"] = (d.value, d.stderr)
    if "tau_e" in out and "delay" in out:
        if _both_decisive(use, model, both):
            out["both"] = True
            return out
        if d.value < MIN_SAMPLES * dt:  # under 2 samples and not needed beside the lag
            out.pop("delay")
            return out
        # a lag and a latency together that the steps do not tell apart: on voltage and speed
        # alone they trade off (both late onsets; the course-lab kit's 2 kHz steps gave 1.8 ms
        # of lag and 2.0 +- 0.6 ms of latency, the lag alone fitting as well, and the lag
        # model then predicted its held-out runs worse, 0.053 against 0.033). Kept as a
        # latency, as before, and said
        out["lag_and_latency"] = (out.pop("tau_e")[0], out["delay"][0])
    if "tau_e" not in out:  # no lag: the latency as the kernel's shift finds it
        out.pop("J")
        if shift:
            out["delay"] = shift
        else:
            out.pop("delay", None)
    return out


#: most refits :func:`profile_bound` takes, each at twice the last lag
BOUND_REFITS = 4
#: the shortest lag [sample periods] :func:`profile_bound` checks first
BOUND_FIRST = 0.125


def profile_bound(use, model, both, local: float, dt: float) -> float:
    """The lag [s] the steps leave open, checked on their cost: the steps' fit with tau_e held
    at the bound (J, bv, bc, the latency and the dead-zone fit's extras free) must rise by two
    standard errors' worth (4 x the reduced chi-square); where it does not, the lag held at
    twice that, up to :data:`BOUND_REFITS` times (the last lag tried is then the bound).
    ``local``: tau_e + 2 standard errors of ``both`` at its solution, a curvature read where
    tau_e lies at its floor: at 100 Hz it put L/R 3.0 ms below 3 us (bench/lumped_coverage.py's
    seed 4) and 3.8 ms below 2.6 and 1.1 ms (tests/identify/test_latency.py). Starts at
    ``local`` or :data:`BOUND_FIRST` of a sample ``dt`` [s], whichever is longer.

    Never beyond :func:`lag_ceiling`: the lag a lumped model folds is the fast one of its two
    modes, so steps that cannot bound it below their own mechanical time constant bound it
    there (a coreless motor's steps under PWM discontinuous conduction, bench/newrigs.py
    dcm-pwm seed 13: a flat cost read as "tau_e below 9 s", which the model file cannot hold)."""
    v = {k: e.value for k, e in both.estimates.items()}
    extra = tuple(k for k in PINNED if k in v)
    rise = 4.0 * max(both.stats.redchi, 1.0)
    ceiling = lag_ceiling(v)
    tau = min(max(local, BOUND_FIRST * dt), ceiling)
    for _ in range(BOUND_REFITS - 1):
        held = _lag_fit(use, model, {**v, "tau_e": tau}, hold="tau_e", extra=extra)
        if held is None or held.stats.chisqr - both.stats.chisqr >= rise or tau >= ceiling:
            return tau
        tau = min(2.0 * tau, ceiling)
    return tau


def lag_ceiling(values: dict) -> float:
    """The longest electrical lag [s] a lumped model folds: its mechanical time constant J/bv
    (per volt, ``values`` holding J and bv) and at most the model file's bound on tau_e
    (:mod:`pmdcid.model.spec`). A longer lag is no longer the fast mode the model folds into J."""
    spec = param_spec("tau_e")
    tau_m = values["J"] / values["bv"] if values.get("bv", 0.0) > 0 else math.inf
    return min(tau_m, spec.upper) if math.isfinite(tau_m) and tau_m > 0 else spec.upper


#: a lag and a latency are both kept only where dropping either raises the steps' BIC by more
#: than this: the pair has the lowest BIC of the three (a sensor-delay red team's steps at
#: 500 Hz, L/R 2 ms and 4 ms of delay: the pair 6.3 below the delay alone, 215 below the lag
#: alone; the course-lab kit's: the lag alone 9.5 below the pair)
BOTH_BIC = 0.0


def _both_decisive(use, model, both) -> bool:
    """Whether the steps need the lag and the latency together: the fit with either held at 0
    (the other starting at their sum) worse by more than :data:`BOTH_BIC` in BIC."""
    v = {k: e.value for k, e in both.estimates.items()}
    tot = v["tau_e"] + v["delay"]
    extra = tuple(k for k in PINNED if k in v)
    singles = [_lag_fit(use, model, {**v, "tau_e": tot, "delay": 0.0}, hold="delay",
                        extra=extra),
               _lag_fit(use, model, {**v, "tau_e": 0.0, "delay": tot}, hold="tau_e",
                        extra=extra)]
    return all(f is not None and f.stats.bic - both.stats.bic > BOTH_BIC for f in singles)


#: what the dead-zone fit frees beside the lag fit's parameters (:func:`_dead_zone_fit`)
PINNED = ("dz", "ke_share")


def _lag_fit(use, model, start: dict, hold: str | None = None, extra: tuple = ()):
    """J, bv, bc, tau_e and the delay (``hold`` held at its start), and ``extra`` (of
    :data:`PINNED`), fitted to the speed of the step logs ``use`` from ``start``; None where
    the fit fails."""
    from pmdcid.errors import PmdcidError
    from pmdcid.fit.parameters import Parameters
    from pmdcid.fit.simfit import FitOptions, fit_simulation

    free = [p for p in ("J", "bv", "bc", "tau_e", "delay", *extra) if p != hold]
    params = Parameters.of(free, start, steps={"bc": 1e-2, "dz": 1e-2, "ke_share": 1e-2})
    if hold is not None:
        params.fix(hold, start[hold])
    try:
        return fit_simulation(use, model, params, ("omega",), options=FitOptions(max_nfev=100))
    except PmdcidError:
        return None


__all__ = ["LAG_SIGMAS", "MIN_SAMPLES", "parabola_min", "shift_curve", "step_lag",
           "step_latency"]
