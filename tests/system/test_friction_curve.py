"""friction_curve: speed-dependent friction that follows no named law (issue #13 item 5).

Round trips on the paper's motor (base parameters moved +-20 %), the paper's three stages, then
diagnose on every log: a friction curve in the kernel, and separately a smooth physical shape
that is not the piecewise form (friction rising then flattening, A*tanh(|omega|/ws), simulated
by a small independent integrator below), are named ``friction_curve`` and the held-out error
drops; pure quadratic drag, positive or negative, is still named ``quadratic_drag``. Plus the
kernel term, the positivity guard and the named-law preference rule on their own.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from ident_util import as_log, blocked_logs, perturbed_truth, step_logs, triangle_log
from numba import njit

from pmdcid.diagnose import diagnose
from pmdcid.diagnose.named import NAMED_MARGIN, generalises, prefer_named
from pmdcid.identify.electrical import fit_electrical
from pmdcid.identify.mechanical import fit_mechanical
from pmdcid.identify.nonlinear import fit_nonlinear
from pmdcid.model import Model
from pmdcid.model.effects.friction import lowest_friction
from pmdcid.simulate import neutral_values, param_values, param_vector, simulate_values
from pmdcid.simulate.terms import friction_curve, sliding_friction
from pmdcid.synth import PAPER, PAPER_NOISE, staircase, step, triangle

#: a friction curve (knot speeds [rad/s], values [N m]) rising steeply, then flat over the logged
#: speeds (about 1 rad/s at most): no named law follows it
CURVE = {"fcw1": 0.15, "fcw2": 0.4, "fcw3": 1.0, "fcw4": 2.0,
         "fc1": 0.006, "fc2": 0.008, "fc3": 0.008}
#: smooth flattening friction added to bc + bv*|omega|: A [N m] * tanh(|omega| / ws [rad/s])
TANH = (0.01, 0.3)


def stages(logs, truth):
    """fit-electrical, fit-mechanical, fit-nonlinear (km from the datasheet)."""
    model = Model()
    model.set("km", truth["km"], stage="datasheet")
    fit_electrical(logs[:5], model).apply(model)
    fit_mechanical(logs[5:10], model).apply(model)
    fit_nonlinear([logs[10]], model).apply(model)
    return model


def nrmse(sim, ref) -> float:
    return float(np.sqrt(np.mean((sim - ref) ** 2)) / np.std(ref))


def held_input(seed: int):
    """A random staircase of +-2 V held 3 s, 60 s at 1 kHz (no fit sees it)."""
    t = np.arange(60000) / 1000.0
    return t, staircase(t, 2.0, 3.0, np.random.default_rng(seed))


# --- an independent integrator for a smooth friction law (not the kernel's piecewise form) ----


@njit(cache=True)
def _smooth_run(u, dt, R, L, km, J, bv, bc, dz, amp, ws, nsub):  # pragma: no cover - compiled
    """Voltage-driven motor with friction bc*sign + bv*omega + amp*tanh(|omega|/ws)*sign and
    the paper's hard dead zone; exact current step per substep, semi-implicit speed, true stick
    (the rotor stays at rest while |torque| <= bc). Returns (i, omega, theta) per sample."""
    n = len(u)
    out = np.empty((n, 3))
    i = 0.0
    w = 0.0
    th = 0.0
    h = dt / nsub
    a = math.exp(-R * h / L)
    for k in range(n):
        out[k, 0] = i
        out[k, 1] = w
        out[k, 2] = th
        for _ in range(nsub):
            i = u[k] / R + (i - u[k] / R) * a
            tm = km * i
            td = tm if abs(tm) >= dz else 0.0
            if w == 0.0 and abs(td) <= bc:
                continue
            d = (1.0 if w > 0 else -1.0) if w != 0.0 else (1.0 if td > 0 else -1.0)
            fr = d * bc + bv * w + d * amp * math.tanh(abs(w) / ws)
            w1 = w + h * (td - fr) / J
            if w1 * d < 0.0:
                w1 = 0.0
            th += 0.5 * h * (w + w1)
            w = w1
    return out


def smooth_sim(truth, t, u):
    dt = float(t[1] - t[0])
    x = _smooth_run(np.asarray(u, float), dt, truth["R"], truth["L"], truth["km"], truth["J"],
                    truth["bv"], truth["bc"], truth["dz"], TANH[0], TANH[1], 20)
    return x


def smooth_log(name, t, u, truth, rng, kind):
    x = smooth_sim(truth, t, u)
    n = len(t)
    q = 2 * np.pi / PAPER_NOISE.encoder
    return as_log(name, t, {"v": u, "i": x[:, 0] + rng.normal(0, PAPER_NOISE.i, n),
                            "omega": x[:, 1] + rng.normal(0, PAPER_NOISE.omega, n),
                            "theta": np.round(x[:, 2] / q) * q}, kind)


def smooth_logs(truth, rng):
    """The paper's protocols on the smooth-friction motor (blocked rotor: friction plays no
    part, the kernel makes them)."""
    ts = np.arange(3000) / 1000.0
    steps = [smooth_log(f"step_{a}V", ts, step(ts, a, 0.5), truth, rng, "free-speed-step")
             for a in (0.5, 1.0, 1.5, 2.0, 2.5)]
    tt = np.arange(20000) / 1000.0  # one period (two took 27 s of the suite; seeds 902, 903
    # on one: friction_curve added, the held-out staircase 0.076 -> 0.009 and 0.050 -> 0.009)
    tri = smooth_log("triangle", tt, triangle(tt, 2.0, 20.0), truth, rng, "triangle")
    return [*blocked_logs(truth, rng), *steps, tri]


# --- round trips -------------------------------------------------------------------------------


@pytest.mark.slow
def test_kernel_curve_is_named_and_fixes_the_held_out_error():
    rng = np.random.default_rng(901)
    truth = perturbed_truth(rng, 0.2, **CURVE)
    logs = [*blocked_logs(truth, rng), *step_logs(truth, rng), triangle_log(truth, rng)]
    model = stages(logs, truth)
    res = diagnose(logs, model)
    assert res.summary["added"] == ["friction_curve"], res.table()
    t, u = held_input(901)
    ref = simulate_values(t, u, truth, False).omega
    before = nrmse(simulate_values(t, u, param_values(model), False).omega, ref)
    after = nrmse(simulate_values(t, u, param_values(res.model), False).omega, ref)
    assert after * 3 <= before and after <= 0.02, (before, after)
    # the knot speeds are written beside the knot values, with units
    assert res.model.parameters["fcw4"].unit == "rad/s"
    assert res.model.parameters["fc1"].unit == "N m"


@pytest.mark.slow
def test_smooth_flattening_friction_is_named_and_fixes_the_held_out_error():
    rng = np.random.default_rng(902)
    truth = perturbed_truth(rng, 0.2)
    logs = smooth_logs(truth, rng)
    model = stages(logs, truth)
    res = diagnose(logs, model)
    assert res.summary["added"] == ["friction_curve"], res.table()
    t, u = held_input(902)
    ref = smooth_sim(truth, t, u)[:, 1]
    before = nrmse(simulate_values(t, u, param_values(model), False).omega, ref)
    after = nrmse(simulate_values(t, u, param_values(res.model), False).omega, ref)
    assert after * 2 <= before, (before, after)


@pytest.mark.slow
@pytest.mark.parametrize("bq", [2e-3, -2e-3])
def test_pure_quadratic_drag_is_named_not_the_curve(bq):
    seed = 910 + int(bq > 0)
    rng = np.random.default_rng(seed)
    truth = perturbed_truth(rng, 0.2, bq=bq)
    logs = [*blocked_logs(truth, rng), *step_logs(truth, rng), triangle_log(truth, rng)]
    model = stages(logs, truth)
    res = diagnose(logs, model)
    assert res.summary["added"] == ["quadratic_drag"], res.table()
    assert res.model.value("bq") == pytest.approx(bq, rel=0.15)


# --- the pieces --------------------------------------------------------------------------------


def test_curve_term_is_piecewise_linear_zero_at_both_ends():
    p = param_vector({**neutral_values(), **PAPER, **CURVE})
    speeds = np.linspace(0.0, 2.5, 101)
    knots = [0.0] + [CURVE[f"fcw{k}"] for k in range(1, 5)]
    values = [0.0] + [CURVE[f"fc{k}"] for k in range(1, 4)] + [0.0]
    want = np.interp(speeds, knots, values, right=0.0)
    assert want[-1] == 0.0 and want[10] > 0.005  # zero past the last knot, not zero inside
    got = np.array([friction_curve(p, s) for s in speeds])
    np.testing.assert_allclose(got, want, atol=1e-15)
    # direction-symmetric, and off when the knots are neutral
    assert sliding_friction(p, -0.7, -1.0) == pytest.approx(-sliding_friction(p, 0.7, 1.0))
    off = param_vector({**neutral_values(), **PAPER})
    assert friction_curve(off, 1.0) == 0.0


def test_friction_never_drives_the_rotor():
    """A negative quadratic drag past the speeds it was fitted on: the kernel holds the total
    friction at zero instead of letting it accelerate the rotor."""
    vals = {**neutral_values(), **PAPER, "bq": -0.01}
    p = param_vector(vals)
    for w in (0.5, 3.0, 10.0):
        total = sliding_friction(p, w, 1.0) + vals["bv"] * w
        assert total >= 0.0
    assert sliding_friction(p, 10.0, 1.0) + vals["bv"] * 10.0 == 0.0  # would be -0.69 N m
    low, at = lowest_friction(vals, 10.0)
    assert low < 0 and at > 3.0  # the unclamped total, which diagnose refuses within logs


def _cand(effect, dbic):
    return SimpleNamespace(effect=effect, delta_bic=dbic, reason="passes")


def test_a_named_law_that_suffices_is_preferred():
    curve, quad = _cand("friction_curve", -1005.0), _cand("quadratic_drag", -1000.0)
    assert prefer_named(curve, [curve, quad]) is quad
    assert "quadratic_drag explains it about as well" in curve.reason
    assert "preferred to friction_curve" in quad.reason
    curve, quad = _cand("friction_curve", -1000.0 - 2 * NAMED_MARGIN), _cand("quadratic_drag",
                                                                              -1000.0)
    assert prefer_named(curve, [curve, quad]) is curve
    assert "beats the best named law" in curve.reason
    alone = _cand("friction_curve", -50.0)
    assert prefer_named(alone, [alone, _cand("cogging", -40.0)]) is alone


def test_a_curve_that_does_not_generalise_is_refused():
    """The curve's held-out gain must be at least half its fit gain (the rule's own numbers)."""
    c = SimpleNamespace(effect="friction_curve", delta_bic=-2295.0, gain_fit=0.268,
                        gain_held=0.06)
    assert "must generalise" in generalises(c)
    c.gain_held = 0.2
    assert generalises(c) is None
    named = SimpleNamespace(effect="quadratic_drag", delta_bic=-2295.0, gain_fit=0.268,
                            gain_held=0.06)
    assert generalises(named) is None  # a named law is judged by the common rules alone


def test_exporters_take_the_curve(tmp_path):
    """Every format writes the curve's knots (their agreement with simulate on a log crossing
    them: tests/export/test_ports.py, tests/system/test_export_native.py)."""
    from pmdcid.export import export_model
    from pmdcid.model import save_model

    m = Model()
    for k, v in PAPER.items():
        m.set(k, v)
    m.add_effect("friction_curve")
    for k, v in CURVE.items():
        m.set(k, v)
    path = tmp_path / "m.json"
    save_model(m, str(path))
    for fmt, name in (("python-control", "motor.py"), ("c", "motor.c"), ("matlab", "motor.m")):
        export_model(str(path), fmt, str(tmp_path / name))
        assert repr(CURVE["fcw4"]) in (tmp_path / name).read_text(), fmt
