"""Real drives: a command applied late (input_delay), back-EMF on logs with current, and the
drive warnings (slow PWM carrier, large drive drop, sensor delay without current).

Round trips: logs simulated from known parameters with noise from ``default_rng(seed)``; diagnose
must name the effect and recover its parameter within the stated tolerance, and each warning
must trigger on a log that shows its cause and stay silent on a clean one.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from ident_util import as_log, blocked_logs, paper_stages, perturbed_truth, step_logs, triangle_log
from repo_paths import REAL

from pmdcid.diagnose import diagnose
from pmdcid.diagnose.drive_warnings import carrier_line, command_lost, drop_warning, latency_warning
from pmdcid.identify.electrical import fit_electrical
from pmdcid.identify.mechanical import fit_mechanical
from pmdcid.identify.nonlinear import fit_nonlinear
from pmdcid.model import Model
from pmdcid.simulate import neutral_values, simulate_values
from pmdcid.simulate.input_grid import MIN_PARTS
from pmdcid.synth import PAPER, NoiseSpec, synth_log, triangle

REAL = REAL

#: a course-lab gear motor on a 12 V PWM drive (MotorXplorer-like, SI): at 12 V its back-EMF
#: leaves about 0.2 A where R alone would pass 3.5 A
COURSE = {"R": 3.4, "L": 2.85e-3, "km": 0.048, "ke": 0.048, "J": 1.0e-5, "bv": 3.0e-5,
          "bc": 3.0e-3, "dz": 0.0}
#: its sensors: current [A] and speed [rad/s] noise
COURSE_NOISE = NoiseSpec(i=5e-3, omega=0.4)


# --- input_delay: the kernel ----------------------------------------------------------------

def _linear_paper() -> dict:
    """The paper's motor without its friction events: the kernel is exact for it."""
    return {**neutral_values(), **PAPER, "bc": 0.0, "dz": 0.0}


def _shifted(u: np.ndarray, dt: float, vals: dict, shift: int, m: int):
    """Reference: the input on a grid m times finer, shifted by ``shift`` fine samples (a delay
    that is an exact multiple of dt/m), simulated without any delay; at the log's instants."""
    n = len(u)
    uf = np.concatenate((np.full(shift, u[0]), np.repeat(u, m)))[: n * m]
    r = simulate_values(np.arange(n * m) * dt / m, uf, vals, nsub=1)
    return r.i[::m], r.omega[::m]


def test_late_input_is_exact_on_its_grid_and_second_order_between():
    vals = _linear_paper()
    dt, n = 1e-3, 400
    u = np.zeros(n)
    u[50:], u[200:], u[300:] = 2.0, 1.0, -1.5
    t = np.arange(n) * dt
    # a latency on the fine grid (dt/8: 3.5 ms = 28 parts) is exact to rounding
    a = simulate_values(t, u, {**vals, "latency": 3.5e-3})
    ri, ro = _shifted(u, dt, vals, 28, MIN_PARTS)
    assert np.max(np.abs(a.i - ri)) <= 1e-10 * np.ptp(ri)
    assert np.max(np.abs(a.omega - ro)) <= 1e-10 * np.ptp(ro)
    # between grid points (3.71 ms) the switch is averaged over dt/8: error << 0.1 % of range
    a = simulate_values(t, u, {**vals, "latency": 3.71e-3})
    ri, ro = _shifted(u, dt, vals, 371, 100)
    assert np.max(np.abs(a.i - ri)) <= 1e-4 * np.ptp(ri)
    assert np.max(np.abs(a.omega - ro)) <= 1e-4 * np.ptp(ro)


def test_input_delay_is_off_at_neutral_moves_the_current_and_is_continuous():
    vals = {**neutral_values(), **PAPER}
    t = np.arange(2000) / 1000.0
    u = 2.0 * (t >= 0.1)
    off = simulate_values(t, u, vals)
    assert np.array_equal(simulate_values(t, u, {**vals, "latency": 0.0}).i, off.i)
    late = simulate_values(t, u, {**vals, "latency": 0.02})
    seen = simulate_values(t, u, {**vals, "delay": 0.02})
    # a late input delays the current too; a late sensor does not
    assert np.max(np.abs(seen.i - off.i)) == 0.0
    k = np.argmax(off.i > 0.5 * off.i.max())
    assert late.i[k] < 0.1 * off.i[k] and late.i[k + 20] == pytest.approx(off.i[k], rel=0.02)
    # a finite-difference Jacobian needs the states to move continuously with the latency
    d1 = simulate_values(t, u, {**vals, "latency": 0.0100})
    d2 = simulate_values(t, u, {**vals, "latency": 0.0101})
    assert 0 < np.max(np.abs(d2.i - d1.i)) <= 0.05 * np.ptp(off.i)


# --- input_delay: diagnose round trip ---------------------------------------------------------

@pytest.mark.slow
def test_input_delay_is_named_and_its_latency_recovered():
    """The paper's three protocols with the command applied 4 ms late (a few ms: a host-paced
    loop): diagnose names input_delay alone and recovers the latency within 5 %."""
    rng = np.random.default_rng(601)
    truth = perturbed_truth(rng, 0.2, latency=4e-3)
    logs, model = paper_stages(truth, rng)
    res = diagnose(logs, model)
    assert res.summary["added"] == ["input_delay"], res.table()
    assert res.model.value("latency") == pytest.approx(4e-3, rel=0.05)


# --- back-EMF on logs with current --------------------------------------------------------------

def _course_logs(truth: dict, rng: np.random.Generator) -> list:
    return [*blocked_logs(truth, rng, (1.0, 2.0, 3.0), COURSE_NOISE, 20000.0, 0.02, 0.002),
            *step_logs(truth, rng, (3.0, 6.0, 9.0, 12.0), COURSE_NOISE, 0.5, 0.05),
            triangle_log(truth, rng, 2, 4.0, 12.0, COURSE_NOISE)]


def _steady_ke(steps: list, R: float) -> float:
    """Slope of the steady-state (v - R i) against omega over the steps' last 30 %."""
    x, y = [], []
    for lg in steps:
        s = slice(int(0.7 * lg.n), lg.n)
        x.append(np.mean(lg["omega"][s]))
        y.append(np.mean(lg["v"][s] - R * lg["i"][s]))
    return float(np.polyfit(x, y, 1)[0])


@pytest.mark.slow
def test_back_emf_found_on_logs_with_current():
    """A model fitted as the paper does (no back-EMF) predicts 7x the current of a course-lab
    motor at speed (its viscous friction swallows the back-EMF's damping): diagnose adds
    back_emf, its ke agrees with the steady-state (v - R i) against omega within 5 %, and the
    viscous friction comes back to the truth."""
    rng = np.random.default_rng(41)
    truth = {**neutral_values(), **COURSE}
    for k in ("R", "J", "bv", "bc"):
        truth[k] *= rng.uniform(0.9, 1.1)
    logs = _course_logs(truth, rng)
    model = Model()
    model.set("km", truth["km"], stage="datasheet")
    fit_electrical(logs[:3], model).apply(model)
    fit_mechanical(logs[3:7], model).apply(model)
    fit_nonlinear([logs[7]], model).apply(model)
    assert model.value("bv") > 5 * truth["bv"]  # the back-EMF's damping, taken as friction
    res = diagnose(logs, model)
    assert res.summary["added"] == ["back_emf"], res.table()
    ke, ke_ss = res.model.value("ke"), _steady_ke(logs[3:7], model.value("R"))
    assert ke == pytest.approx(ke_ss, rel=0.05)
    assert ke == pytest.approx(truth["ke"], rel=0.02)
    assert res.model.value("bv") == pytest.approx(truth["bv"], rel=0.3)


# --- slow PWM carrier -------------------------------------------------------------------------

def _pwm(command: np.ndarray, t: np.ndarray, carrier: float, vbus: float = 12.0) -> np.ndarray:
    """The voltage a PWM drive applies for ``command`` [V] at ``carrier`` [Hz]: vbus while
    the carrier's phase is below the duty |command|/vbus, else 0 (terminals shorted)."""
    phase = np.mod(t * carrier, 1.0)
    return np.sign(command) * vbus * (phase < np.abs(command) / vbus)


def _carrier_logs(rng: np.random.Generator, carrier: float | None):
    """A unipolar triangle 0 -> 10 V (period 4 s, 8 s at 1 kHz) on the course motor; with a
    PWM carrier of ``carrier`` Hz really applied, or (None) the average the log records."""
    truth = {**neutral_values(), **COURSE}
    t = np.arange(8000) / 1000.0
    cmd = 5.0 + 5.0 * triangle(t, 1.0, 4.0)
    applied = cmd if carrier is None else _pwm(cmd, t, carrier)
    cols, _ = synth_log(t, applied, truth, COURSE_NOISE, rng)
    cols["v"] = cmd
    return truth, as_log(f"triangle_{carrier or 'avg'}", t, cols, "triangle")


@pytest.mark.parametrize("carrier", [10.0, 100.0])
def test_slow_pwm_carrier_warns_and_a_clean_log_does_not(carrier):
    rng = np.random.default_rng(71)
    truth, slow = _carrier_logs(rng, carrier)
    _, clean = _carrier_logs(rng, None)
    model = Model()
    for k in ("R", "L", "km", "J", "bv", "bc", "dz"):
        model.set(k, truth[k], stage="datasheet")
    model.add_effect("back_emf")
    model.set("ke", truth["ke"], stage="datasheet")
    res = diagnose([slow, clean], model, effects=["stribeck"])
    warned = [w for w in res.summary["warnings"] if "PWM carrier" in w]
    assert len(warned) == 1, res.summary["warnings"]
    assert slow.path in warned[0] and clean.path not in warned[0]
    f = float(warned[0].split(slow.path)[1].split("Hz")[0])
    assert f == pytest.approx(carrier, rel=0.02)


def test_a_ripple_locked_to_the_angle_is_not_a_carrier():
    """Cogging at a steady speed is a fixed frequency in time too, but a whole number of lines
    per revolution: not a carrier."""
    rng = np.random.default_rng(73)
    truth = {**neutral_values(), **COURSE, "ca": 2e-3, "cn": 2.0}
    t = np.arange(4000) / 1000.0
    cols, _ = synth_log(t, 8.0 * (t >= 0.2), truth, COURSE_NOISE, rng)
    ref = simulate_values(t, cols["v"], {**truth, "ca": 0.0})
    assert carrier_line(t, cols["v"], cols["omega"], cols["omega"] - ref.omega) is None


#: lumped (per volt) model of the pboon rig, fitted by `pmdcid identify` on step_10, step_100,
#: step_100000 and ramp_100000 (steps at 12 V are duty 1: no carrier), written here to save time
PBOON = {"J": 3.666e-3, "bv": 4.639e-2, "bc": 1.892, "dz": 3.411}


@pytest.mark.skipif(not (REAL / "fra233-2025-pboon").is_dir(), reason="real rigs not here")
def test_real_slow_carriers_are_seen_and_fast_ones_not():
    """pboon's ramps and staircases at 10 Hz and 100 Hz PWM ripple at the carrier; the same
    protocols at 100 kHz do not."""
    from pmdcid.io import read_logs
    from pmdcid.model.lumped import mark_lumped
    from pmdcid.simulate import logs_for, simulate_log

    model = Model()
    for k, v in PBOON.items():
        model.set(k, v, stage="identify")
    mark_lumped(model)
    for name, carrier in [("ramp_10", 10.0), ("stair_100", 100.0), ("triangle_10", 10.0),
                          ("ramp_100000", None), ("stair_100000", None)]:
        log = logs_for(read_logs([str(REAL / "fra233-2025-pboon" / f"{name}.csv")]), model)[0]
        sim = simulate_log(log, model)
        hit = carrier_line(log.t, log.u, log["omega"], log["omega"] - sim.omega)
        if carrier is None:
            assert hit is None, (name, hit)
        else:
            assert hit is not None and hit[0] == pytest.approx(carrier, rel=0.02), (name, hit)


# --- drive drop and latency without current -----------------------------------------------------

def _problem(u_max: float, lumped: bool, current: bool, dt: float = 1e-3):
    log = SimpleNamespace(u=np.array([0.0, u_max]), meta={"lumped": "true"} if lumped else {},
                          t=np.arange(100) * dt)
    return SimpleNamespace(logs=[log], measures=lambda s: current and s == "i")


def test_a_large_drive_drop_warns_and_a_small_one_does_not():
    """A per-volt model whose command moves the rotor only above 2.4 V of 24 V (the L298N rig)
    warns; one that moves at 0.5 V does not; brush_drop on a model with current warns."""
    vals = {**neutral_values(), "J": 0.05, "bv": 0.7, "bc": 2.4, "dz": 1.0}
    assert command_lost(vals, 24.0) == pytest.approx(2.4, abs=0.02)
    assert "loses 2.4" in drop_warning(_problem(24.0, True, False), vals, [])
    assert drop_warning(_problem(24.0, True, False), {**vals, "bc": 0.5, "dz": 0.2}, []) is None
    assert drop_warning(_problem(24.0, False, True), vals, []) is None
    w = drop_warning(_problem(24.0, False, True), {**vals, "R": 3.4, "vb": 1.8}, ["brush_drop"])
    assert "vb = 1.8 V" in w and "R = 3.4" in w


def test_an_undetermined_dead_zone_is_read_from_its_low_end():
    """A dead zone the logs do not determine (its standard error over a quarter of the Coulomb
    friction, the fit stages' "poorly determined") is said from its low end, the fitted value's
    loss as the upper: the L298N's steps all move, and a model of them held dz = 5.1 +- 4.4 V
    (session 33), which read as "loses 3.65 V" before; a determined one is said as it is."""
    vals = {**neutral_values(), "J": 0.05, "bv": 0.7, "bc": 2.4, "dz": 5.1}
    model = Model()
    model.set("bc", 2.4, 0.02)
    model.set("dz", 5.1, 4.4)
    w = drop_warning(_problem(24.0, True, False), vals, [], model)
    assert "V or more (up to 5.1 V" in w, w
    assert float(w.split("loses ")[1].split(" V")[0]) == pytest.approx(2.4, abs=0.02)
    model.set("dz", 5.1, 0.1)
    assert "loses 5.1 V (" in drop_warning(_problem(24.0, True, False), vals, [], model)


def test_a_sensor_delay_without_current_may_be_latency():
    vals = {**neutral_values(), "delay": 3.5e-3}
    assert "3.5 ms" in latency_warning(_problem(12.0, True, False), vals, ["sensor_delay"])
    assert latency_warning(_problem(12.0, False, True), vals, ["sensor_delay"]) is None
    assert latency_warning(_problem(12.0, True, False), vals, []) is None
    assert "half a sample" not in latency_warning(_problem(12.0, True, False), vals,
                                                  ["sensor_delay"])


def test_a_sensor_delay_of_half_a_sample_is_said_to_be_a_counted_speed():
    """Encoder counts per 20 ms period: the speed is the period's mean, 10 ms late."""
    vals = {**neutral_values(), "delay": 10.2e-3}
    line = latency_warning(_problem(12.0, True, False, dt=0.02), vals, ["sensor_delay"])
    assert "half a sample period (20 ms)" in line and "counts per period" in line


def test_exporters_take_a_late_input():
    """The exporters step the late input themselves (agreement with simulate:
    tests/export/test_ports.py, tests/system/test_export_native.py): the latency is in the
    exported values,
    0 when the effect is off."""
    from pmdcid.export import spec_of

    model = Model()
    for k in ("R", "L", "km", "J", "bv", "bc", "dz"):
        model.set(k, PAPER[k], stage="datasheet")
    assert spec_of(model).values["latency"] == 0.0
    model.add_effect("input_delay")
    model.set("latency", 4e-3, stage="diagnose")
    assert spec_of(model).values["latency"] == 4e-3


@pytest.mark.skipif(not (REAL / "guanlunlu-l298n").is_dir(), reason="real rigs not here")
def test_real_l298n_drop_is_warned_about():
    """`identify` on the L298N rig's first runs (lumped: voltage and speed only) says that the
    command loses about the README's 2.4 V intercept before the motor turns."""
    from pmdcid import api

    paths = [str(REAL / "guanlunlu-l298n" / f"step_{v}V_1.csv") for v in (6, 12, 24)]
    res = api.identify(paths, progress=False)
    lost = [w for w in res.diagnose.summary["warnings"] if "the command loses" in w]
    assert len(lost) == 1, res.diagnose.summary["warnings"]
    volts = float(lost[0].split("loses ")[1].split(" V")[0])
    assert 1.9 <= volts <= 2.9, lost
