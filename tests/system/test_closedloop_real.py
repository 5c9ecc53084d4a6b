"""Closed-loop real rigs (../shared/data, never copied here; skipped only when absent):
micromouse-pid against the linear baseline, its controller spec against its own logged commands,
and EMPS's documented PD loop simulated with the authors' parameters (docs/real-data.md,
docs/examples/emps.md; figures by ``python -m bench.closedloop``)."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from bench import closedloop, realdata
from pmdcid.simulate.controller import ControllerState, controller_from_dict

MOUSE = closedloop.MICROMOUSE
need_mouse = pytest.mark.skipif(not MOUSE.is_dir(), reason=f"no {MOUSE}")
need_emps = pytest.mark.skipif(not closedloop.EMPS.is_dir(), reason=f"no {closedloop.EMPS}")


@need_mouse
def test_micromouse_spec_reproduces_its_logged_commands():
    """The spec bench/closedloop.py gives the micromouse's loop, fed the logged speed and
    reference, reproduces the logged PWM command step by step on at least 97 % of the steps
    (measured 98-99 %; the others one count off at a threshold of the floor)."""
    spec = controller_from_dict(closedloop.MICROMOUSE_SPEC)
    for name in closedloop.FIT + closedloop.HELD:
        lg = closedloop.read_loop_timed(MOUSE / name)
        # each step from the logged previous command: the increments, not a drifting sum
        inc = np.diff(np.round(np.asarray(lg["v"]) / spec.quantum))
        c = ControllerState(spec)
        same = []
        for k in range(1, lg.n):
            c.u_prev = float(lg["v"][k - 1])
            du = c.step(lg.extra["omega_ref"][k], lg["omega"][k], 0.0) - lg["v"][k - 1]
            same.append(round(du / spec.quantum) == inc[k - 1])
        assert np.mean(same) >= 0.97, (name, np.mean(same))


@functools.cache
def _mouse_held_out() -> tuple[float, float]:
    """(identify's, the linear baseline's) mean held-out speed NRMSE: fitted on the 1 and 10 ms
    controller periods, the 2 and 5 ms runs predicted from their logged commands."""
    from pmdcid.model import Model
    from pmdcid.pipeline import identify

    fit = [closedloop.uniform_log(MOUSE / n) for n in closedloop.FIT]
    held = [closedloop.uniform_log(MOUSE / n) for n in closedloop.HELD]
    lin = realdata.fit_linear(fit)
    linear = np.mean([realdata.nrmse(realdata.linear_sim(lin, lg), lg["omega"]) for lg in held])
    model = identify(fit, Model()).model
    return float(np.mean([realdata.predict(model, lg) for lg in held])), float(linear)


@need_mouse
@pytest.mark.slow
def test_micromouse_identify_beats_the_linear_baseline():
    """Issue 24: a closed-loop log must not end worse than a linear fit. It did (0.250 against
    0.223) while the AR noise model whitened the residual's slow drift, the model's own error;
    with only a sensor's colour whitened it gives 0.207 (docs/identification.md)."""
    ours, linear = _mouse_held_out()
    assert ours < 0.97 * linear, (ours, linear)


@need_mouse
@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="issue 24's micromouse target is not met: identify 0.207 "
                   "against the linear baseline's 0.223 and the target's 0.112; out of reach "
                   "for this model class: Stribeck friction and a sensor delay fitted on all "
                   "four runs, the held-out ones included, give 0.17 (docs/real-data.md, "
                   "bench/rig_limits.py)")
def test_micromouse_held_out_against_the_linear_baseline():
    """The issue's target: half the linear baseline; this asks for 0.85 of it. It was met once
    (0.160) while diagnose added quadratic drag and Stribeck friction; the two fit logs hold out
    only their steady tails at the 200 rpm target, which cannot test a speed law, so diagnose
    leaves them as "possible, not testable". Strict: it fails loudly once this passes."""
    ours, linear = _mouse_held_out()
    assert ours < 0.85 * linear, (ours, linear)


@need_emps
def test_emps_closed_loop_with_the_authors_parameters():
    """EMPS's PD loop (EMPS_Description.txt eq. 6-7) simulated from the reference with the
    authors' parameters: on the validation file (pulses fed forward) the position within 0.05 %
    (measured 0.029 %; the authors' Simulink: 0.008 %), the velocity within 0.5 % (0.19 %;
    theirs 0.48 %) and the force within 7 % (5.85 %; theirs 8.9 %)."""
    from pmdcid.io import parse_mapping, read_log

    m = parse_mapping(["t=t_s", "tau=force_N", "theta=qm_meas_m"])
    test = read_log(closedloop.EMPS / "emps_test_DATA_EMPS_PULSES.csv", m)
    spec = controller_from_dict({**closedloop.EMPS_SPEC, "feedforward": "pulse_in_vir_units"})
    pos, vel, force = closedloop.emps_errors(test, closedloop.AUTHORS, spec)
    assert pos < 0.05 and vel < 0.5 and force < 7.0, (pos, vel, force)
