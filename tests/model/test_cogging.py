"""The cogging probe's orders come from samples that resolve them (model/effects/cogging.py).

bench/closedloop_redteam.py b+ seed 1 (a speed loop logged every 2-13 ms, up to 3000 rpm, no
cogging in the truth) at main 471418b: diagnose added a cogging of 332 periods per revolution
(ca 1.16 V, three times the Coulomb friction), an order the logs turn through in a hundredth of
a sample. Here: a residual periodic in angle at an order the samples cannot resolve (the rotor
turns 0.5 rad per sample: orders above pi / 0.5 = 6.3 alias) is no probe; one a slow log
resolves is the strongest.
"""

from __future__ import annotations

import numpy as np

from pmdcid.model.effects.cogging import angle_spectrum, signature
from pmdcid.model.residual import LogResidual, ResidualContext


def _log(rng, omega: float, order: int, amp: float, n: int = 4000, dt: float = 1e-2):
    t = np.arange(n) * dt
    theta = omega * t + rng.uniform(0, 2 * np.pi)
    w = np.full(n, omega)
    r = amp * np.sin(order * theta) + rng.normal(0.0, 0.1, n)
    return LogResidual(t, np.ones(n), False, False, w + r, theta, w, {"omega": r})


def _ctx(logs) -> ResidualContext:
    return ResidualContext({}, logs, torque_scale=1e-3, speed_scale=50.0, voltage_scale=12.0,
                           dt=1e-2)


def _orders(ctx) -> list[int]:
    return [int(p.columns[0]["cn"]) for p in signature(ctx)]


def test_an_order_the_samples_alias_is_no_probe():
    rng = np.random.default_rng(3)
    ctx = _ctx([_log(rng, 50.0, 300, 0.5)])
    assert 300 not in _orders(ctx)
    assert angle_spectrum(ctx)[7:].max() == 0.0  # nothing read above what they resolve


def test_an_order_a_slow_log_resolves_is_found_beside_a_fast_one():
    rng = np.random.default_rng(4)
    ctx = _ctx([_log(rng, 50.0, 300, 0.5), _log(rng, 2.0, 12, 0.05)])
    assert _orders(ctx)[0] == 12


def test_a_speed_derived_through_a_low_pass_resolves_orders_only_below_its_cut_off():
    """A speed derived from the angle through a low-pass at f_c shows n periods per revolution
    only where n |omega| < 2 pi f_c: at 2 rad/s and 10 ms samples order 12 is under Nyquist
    (n < 157) but its ripple, 3.8 Hz, is above a 2 Hz cut-off. bench/newrigs.py lego seed 7
    (angle only, 11 ms samples, a 9 Hz cut-off): an order 71 read where the derived speed
    cannot show it was added as cogging and raised the held-out sines 17-30 %."""
    rng = np.random.default_rng(4)
    measured = _log(rng, 2.0, 12, 0.05)
    assert _orders(_ctx([measured]))[0] == 12
    derived = _log(rng, 2.0, 12, 0.05)
    derived.bandwidth = 2.0
    assert angle_spectrum(_ctx([derived]))[4:].max() == 0.0  # 2 pi 2 Hz / 2 rad/s = 6.3
    derived.bandwidth = 5.0  # 3.8 Hz ripple under a 5 Hz cut-off: read
    assert _orders(_ctx([derived]))[0] == 12
