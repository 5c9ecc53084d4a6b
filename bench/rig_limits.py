"""What limits the three real rigs that miss issue 24's targets (docs/real-data.md, emps.md).

    python -m bench.rig_limits [micromouse|emps|pboon]

Each part measures, with pmdcid's own simulator (``simulate_for``, as realbench predicts), how
far a model of the tool's class can go on the rig's logs, and why:

- **micromouse**: fit-nonlinear on the 1 and 10 ms runs with the AR(2) noise model closed-loop
  logs get and with the plain simulation error; the OE residual's size against the speed's
  white-noise level and its AR(2) whitener; then an *oracle*: the base model with Stribeck
  friction and a sensor delay fitted to all four runs at once (held-out runs included), the
  best this model class does on these logs; and any friction law of speed (the friction
  curve's knots free of sign), fitted on the fit runs and, as an oracle, on all four.
- **emps**: the symmetric model fitted on each file (fit-nonlinear, the benchmark's error on
  both); the force diagnose's model lacks on each file, by the validation file's pulse phase
  and direction (where the extra friction of the validation run sits); diagnose's model with
  only its Coulomb friction refitted on the validation file (an oracle: what the validation
  file asks of the friction).
- **pboon**: identify's model with its dead zone (a breakaway that also stops the running
  motor below dz) replaced by Stribeck friction of the same breakaway (held only at rest), the
  base parameters refitted on the fit logs.

Oracles see the held-out data: they bound what any estimator can reach; they are never used
to choose anything in the tool.
"""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import closedloop, realdata  # noqa: E402


def _refit(model, names, logs, free_sign=()):
    """``model`` with ``names`` refitted by speed simulation error (each log's NRMSE squared,
    summed) on ``logs``: a copy. Every parameter is kept >= 0 but those of ``free_sign``."""
    from pmdcid.simulate.measured import simulate_for

    work = model.copy()
    x0 = np.array([work.value(n) for n in names])

    def put(x):
        out = work.copy()
        for n, v in zip(names, x, strict=True):
            out.set(n, float(v))
        return out

    def resid(x):
        m = put(x)
        return np.concatenate([(simulate_for(lg, m).omega - lg["omega"])
                               / (np.std(lg["omega"]) * np.sqrt(lg.n)) for lg in logs])

    low = [-np.inf if n in free_sign else 0.0 for n in names]
    sol = least_squares(resid, x0, x_scale=np.maximum(np.abs(x0), 1e-3), diff_step=0.02,
                        bounds=(low, np.inf), max_nfev=200)
    return put(sol.x)


def _errors(model, logs) -> list[float]:
    return [round(realdata.predict(model, lg), 3) for lg in logs]


def micromouse() -> None:
    from pmdcid.fit.problem import noise_level
    from pmdcid.fit.simfit import ar_whitener
    from pmdcid.identify.runners import per_volt, stage_nonlinear
    from pmdcid.model import Model
    from pmdcid.model.lumped import mark_lumped
    from pmdcid.simulate.measured import simulate_for

    fit = [closedloop.uniform_log(closedloop.MICROMOUSE / n) for n in closedloop.FIT]
    held = [closedloop.uniform_log(closedloop.MICROMOUSE / n) for n in closedloop.HELD]
    lin = realdata.fit_linear(fit)
    print("micromouse linear, held out:",
          [round(realdata.nrmse(realdata.linear_sim(lin, lg), lg["omega"]), 3) for lg in held])
    models = {}
    for order in (2, 0):
        m = Model()
        mark_lumped(m)
        res = stage_nonlinear(fit, m, noise_model=order)
        per_volt(res)
        res.apply(m)
        models[order] = m
        vals = {k: f"{m.value(k):.4g}" for k in ("J", "bv", "bc", "dz")}
        print(f"micromouse fit-nonlinear, AR({order}) noise model: {vals}; held out "
              f"{_errors(m, held)}, fit logs {_errors(m, fit)}")
    for lg in fit:
        r = simulate_for(lg, models[0]).omega - lg["omega"]
        sd = noise_level(lg["omega"])
        a = ar_whitener(r / sd, 2)
        print(f"micromouse {Path(lg.path).name}: OE residual RMS {np.sqrt(np.mean(r ** 2)):.3g} "
              f"rad/s = {np.sqrt(np.mean(r ** 2)) / sd:.1f} x the speed's white-noise level; "
              f"its AR(2) whitener {np.round(a, 3).tolist() if a is not None else None}")
    start = models[0].copy()
    start.add_effect("stribeck")
    start.add_effect("sensor_delay")
    start.set("fs", 0.8)
    start.set("ws", 2.0)
    start.set("delay", 0.01)
    oracle = _refit(start, ["J", "bv", "bc", "dz", "fs", "ws", "delay"], fit + held)
    print(f"micromouse oracle (Stribeck + sensor delay, fitted on all four runs): held out "
          f"{_errors(oracle, held)}, fit logs {_errors(oracle, fit)}")
    _any_friction_law(models[0], fit, held)


def _any_friction_law(model, fit, held) -> None:
    """The bound of any friction law of speed: the friction curve's knot values free of sign
    (the total friction may even turn negative, which no passive friction does) with J, bv,
    bc, fitted on the fit runs, then on all four runs (the oracle)."""
    from pmdcid.model.effects.friction import TOP_QUANTILE
    from pmdcid.model.effects.friction_curve import CURVE_FRACTIONS, CURVE_VALUES

    w = np.abs(np.concatenate([lg["omega"] for lg in fit]))
    top = float(np.quantile(w[w > 0.02 * w.max()], TOP_QUANTILE))
    start = model.copy()
    start.add_effect("friction_curve")
    for k, f in enumerate((*CURVE_FRACTIONS, 1.0)):
        start.set(f"fcw{k + 1}", f * top)
    for n in CURVE_VALUES:
        start.set(n, 0.0)
    names = ["J", "bv", "bc", *CURVE_VALUES]
    for label, logs in (("the fit runs", fit), ("all four runs (oracle)", fit + held)):
        m = _refit(start, names, logs, free_sign=("bv", *CURVE_VALUES))
        law = {n: round(m.value(n), 3) for n in ("bc", "bv", *CURVE_VALUES)}
        print(f"micromouse, any friction law of speed fitted on {label}: {law}; held out "
              f"{_errors(m, held)}, fit logs {_errors(m, fit)}")


def emps() -> None:
    from pmdcid.diagnose import diagnose
    from pmdcid.identify.openloop import velocity_error
    from pmdcid.identify.runners import stage_nonlinear
    from pmdcid.io import parse_mapping, read_log
    from pmdcid.model import Model

    m = parse_mapping(["t=t_s", "tau=force_N", "theta=qm_meas_m"])
    files = {"estimation": read_log(closedloop.EMPS / "emps_train_DATA_EMPS.csv", m),
             "validation": read_log(closedloop.EMPS / "emps_test_DATA_EMPS_PULSES.csv", m)}
    est, val = files["estimation"], files["validation"]

    def errs(model) -> str:
        return (f"error est. {velocity_error(est, model):.2f} %, "
                f"val. {velocity_error(val, model):.2f} %")

    for name, lg in files.items():
        model = Model()
        stage_nonlinear([lg], model).apply(model)  # fit-nonlinear as the command runs it
        vals = {k: f"{model.value(k):.4g}" for k in ("J", "bv", "bc", "tau0")}
        print(f"EMPS symmetric model fitted on the {name} file: {vals}; {errs(model)}")
        if name == "estimation":
            diag = diagnose([lg], model).model
    print(f"EMPS diagnose's model (estimation file): bc {diag.value('bc'):.4g}; {errs(diag)}")
    pulse_on = np.asarray(val.extra["pulse_in_vir_units"]) != 0
    for name, lg in files.items():
        gap = _force_gap(diag, lg, pulse_on)
        print(f"EMPS {name} file, force diagnose's model lacks (opposing the motion) [N]: "
              + ", ".join(f"{k} {v:+.2f}" for k, v in gap.items()))
    oracle = _refit(diag, ["bc"], [val])
    print(f"EMPS oracle, diagnose's model with bc refitted on the validation file: "
          f"bc {oracle.value('bc'):.4g}; {errs(oracle)}")


def _force_gap(model, log, pulse_on) -> dict[str, float]:
    """The mean force [N] ``model`` lacks to move ``log`` as measured, in the direction of
    motion: F - (J a + bv v + dbv |v| + bc sign(v) + tau0) times sign(v), on the speed and
    acceleration derived as the benchmark derives them (100 Hz), over the samples moving faster
    than 10 mm/s, split by the validation file's pulse phase (``pulse_on``: the same instants
    on both files, whose reference trajectories are identical) and direction."""
    from pmdcid.io.derive import kinematics_from_position

    k = kinematics_from_position(log["theta"], log.dt, 100.0)
    v, a = k.omega, k.alpha
    val = {n: model.value(n) if model.has(n) else 0.0
           for n in ("J", "bv", "dbv", "bc", "tau0")}
    need = (val["J"] * a + val["bv"] * v + val["dbv"] * np.abs(v) + val["bc"] * np.sign(v)
            + val["tau0"])
    gap = (np.asarray(log.u) - need) * np.sign(v)
    out = {}
    for phase, on in (("pulse on", pulse_on), ("pulse off", ~pulse_on)):
        for way, sel in (("forward", v > 0.01), ("backward", v < -0.01)):
            out[f"{phase} {way}"] = float(np.mean(gap[on & sel]))
    return out


def pboon() -> None:
    rig = next(r for r in realdata.rigs() if r.name == "fra233-2025-pboon")
    fit = realdata.read(rig, rig.steps + rig.rich)
    held = [lg for names in rig.heldout.values() for lg in realdata.read(rig, names)]
    base = realdata.identify_rig(rig)
    names = ["J", "bv", "bc", "dz"] + (["delay"] if base.has("delay") else [])
    for label, start, free in (
            ("identify", base, None),
            ("identify, base refitted", base, names),
            ("dead zone -> Stribeck, refitted", _stiction(base), names + ["fs", "ws"])):
        model = _refit(start, free, fit) if free else start
        e = _errors(model, held)
        print(f"pboon {label}: held-out mean {np.mean(e):.3f} ({e})")


def _stiction(model):
    """``model`` with its breakaway moved from the dead zone to Stribeck friction: fs = dz - bc,
    dz 0 (the refit moves it)."""
    out = model.copy()
    out.add_effect("stribeck")
    fs = max(out.value("dz") - out.value("bc"), 0.0)
    out.set("dz", 0.1 * out.value("bc"))
    out.set("fs", fs)
    out.set("ws", 2.0)
    return out


def main(argv=None) -> int:
    only = (argv if argv is not None else sys.argv[1:])[:1]
    warnings.simplefilter("ignore")  # the loop-timed logs' one-line resampling notes
    for name, part in (("micromouse", micromouse), ("emps", emps), ("pboon", pboon)):
        if only in ([], [name]):
            part()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
