"""diagnose on a lumped model without an electrical lag: a delay that is the armature's L/R
is written as the lag (diagnose/lag.py).

Found by issue 24's new-user checks: voltage + speed logs of a motor with L/R 2 ms and no
latency, fit-mechanical's steps not resolving the lag; diagnose added a sensor_delay of 1.91 ms
and blamed a host-paced loop's latency. Round trip on per-volt logs (1 kHz, steps up, down and
through zero in the fitted and the held-out part of each, speed noise from default_rng(seed))
from the true model without its lag: diagnose writes tau_e within 5 % and no sensor_delay, and
its own figure is the written model's; logs with a latency and no lag keep the delay.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from ident_util import LUMPED, as_log

from bench.thinlogs import scenario, write
from pmdcid.api import identify
from pmdcid.diagnose.entry import diagnose_logs
from pmdcid.fit.problem import Problem
from pmdcid.io.mapping import parse_mapping
from pmdcid.model import Model
from pmdcid.model.lumped import mark_lumped
from pmdcid.simulate import lumped_view, neutral_values, param_values, simulate_values

LAG = 3e-3
#: the per-volt motor: LUMPED with no dead zone (the lag's dead zone acts on the torque)
MOTOR = {**LUMPED, "dz": 0.0}


def _logs(tau_e: float, delay: float, seed: int):
    rng = np.random.default_rng(seed)
    vals = {**neutral_values(), **MOTOR, "R": 1.0, "L": 1.0, "km": 1.0, "tau_e": tau_e,
            "ke_share": 0.9, "delay": delay}
    t = np.arange(3000) * 1e-3
    out = []
    for k, levels in enumerate(((0.0, 2.0, 1.0, -1.0, 2.5), (0.0, -1.5, 2.5, 1.0, -2.0))):
        u = np.select([t < 0.3, t < 1.0, t < 1.9, t < 2.5], levels[:4], levels[4])
        om = simulate_values(t, u, vals, torque_driven=True, nsub=64).omega
        out.append(as_log(f"s{k}.csv", t, {"v": u, "omega": om + rng.normal(0.0, 0.02, t.size)}))
    return out


def _model() -> Model:
    m = Model()
    for k, v in MOTOR.items():
        m.set(k, v, stage="truth")
    mark_lumped(m)
    return m


@pytest.mark.slow
def test_a_delay_that_is_the_lag_is_written_as_the_lag():
    logs = _logs(LAG, 0.0, seed=5)
    res = diagnose_logs(logs, _model(), effects=["sensor_delay"])
    new = res.model
    assert "sensor_delay" not in new.effects and "sensor_delay" not in res.summary["added"]
    assert new.value("tau_e") == pytest.approx(LAG, rel=0.05)
    # taken in the delay's place in the round that would have added it (diagnose/lawlag.py)
    assert any("electrical lag tau_e = " in n for n in res.summary["notes"])
    # the model written is the model judged: its errors are diagnose's "after"
    problem = Problem([lumped_view(lg) for lg in logs])
    sims = problem.simulate_all(param_values(new))
    rms = [np.sqrt(np.mean((s.omega - lg["omega"]) ** 2)) / np.std(lg["omega"])
           for s, lg in zip(sims, logs, strict=True)]
    after = [row["after"]["omega"] for row in res.summary["logs"]]
    assert rms == pytest.approx(after, rel=1e-6)


@pytest.mark.slow
def test_a_latency_keeps_the_delay():
    res = diagnose_logs(_logs(0.0, LAG, seed=6), _model(), effects=["sensor_delay"])
    assert "sensor_delay" in res.model.effects and not res.model.has("tau_e")
    assert any("kept: the armature's electrical lag" in n for n in res.summary["notes"])


@pytest.mark.slow
def test_a_latency_beside_the_lag_keeps_the_late_start_and_judges_the_lag_beside_it():
    """A real latency (4 samples) and the armature's lag (3 ms): diagnose keeps the delay, and
    the lag is judged both in its place and beside it (diagnose/lag.py, ``_pair``). How the late
    start splits between the two these logs do not pin down: their sum within 5 %. With the
    kernel's continuous zero crossing (session 22) the lag beside the delay is not decisive on
    any of seeds 1-8 (delay 6.9-7.2 ms); before, 3 of 8 kept both (seed 7: 0.9 ms of lag and
    6.2 ms of delay), the sum within 5 % either way."""
    res = diagnose_logs(_logs(LAG, 4e-3, seed=7), _model(), effects=["sensor_delay"])
    new = res.model
    assert "sensor_delay" in new.effects, res.summary["notes"]
    lag = new.value("tau_e") if new.has("tau_e") else 0.0
    assert lag + new.value("delay") == pytest.approx(LAG + 4e-3, rel=0.05)
    judged = [n for n in res.summary["notes"] if n.startswith("sensor_delay (")]
    assert judged and "in its place" in judged[0] and "beside it" in judged[0], judged


class _Run:
    """A diagnose run reduced to what ``lag._pair`` reads: the rules, the sample counts, and
    refits on the fitted part whose held-out chi-square is given per free-parameter set."""

    def __init__(self, held: dict[frozenset, float]):
        from pmdcid.diagnose.settings import Settings

        self.settings, self.held = Settings(), held
        self.problem = self

    def count(self, part: str) -> int:
        return {"all": 10000, "fit": 6000, "held": 4000}[part]

    def envelope_errors(self, vals, free, rel=1e-2):
        """White residuals, the share uncorrelated with the lag: no inflation, rho 0."""
        return {}, None, np.eye(len(free))

    def correlated_stderr(self, vals, free, rel=1e-2):
        return {}, None

    def fit(self, vals, free, part):
        from pmdcid.fit.problem import FitOutcome
        from pmdcid.fit.results import FitStats

        return FitOutcome(dict(vals), {}, FitStats(6000, len(free), 1.0),
                          {"held": self.held[frozenset(free)]})


def _outcome(chi2: float, **est):
    from pmdcid.fit.problem import FitOutcome
    from pmdcid.fit.results import Estimate, FitStats

    return FitOutcome({"delay": 4e-3, **{k: v for k, (v, _) in est.items()}},
                      {k: Estimate(k, v, se, "s") for k, (v, se) in est.items()},
                      FitStats(10000, 5, chi2), {"all": chi2})


def test_a_pair_decisive_on_all_data_is_refused_where_the_held_out_data_do_not_bear_it():
    """The course-lab kit's case (fra233-g04: a lag of a tenth of a sample beside its 4 ms
    latency at ΔBIC -1022 on a residual correlated over 135 samples, its held-out runs 0.029 ->
    0.037): the lag beside the delay is decisive by BIC on all data; taken only where the
    held-out part, both models refitted on the fitted part, is lower with it."""
    from pmdcid.diagnose.lag import _pair

    delay_free, both_free = ["J", "bv", "delay"], ["J", "bv", "delay", "tau_e", "ke_share"]
    ref = _outcome(480957.0, delay=(4e-3, 1e-5))
    both = _outcome(470000.0, delay=(4e-3, 1e-5), tau_e=(5e-5, 1e-6))
    worse = _Run({frozenset(delay_free): 100.0, frozenset(both_free): 147.0})
    dbic, held = _pair(worse, ref, delay_free, both, both_free, min_z=3.0)
    assert dbic < -10 and held == pytest.approx(47.0)  # decisive, refused: held > 0
    better = _Run({frozenset(delay_free): 100.0, frozenset(both_free): 60.0})
    assert _pair(better, ref, delay_free, both, both_free, min_z=3.0)[1] == pytest.approx(-40.0)
    # not decisive on all data: no held-out test, not taken
    close = _outcome(480950.0, delay=(4e-3, 1e-5), tau_e=(5e-5, 1e-6))
    assert _pair(better, ref, delay_free, close, both_free, min_z=3.0)[1] == 0.0


def test_a_pair_whose_lag_a_correlated_residual_leaves_unresolved_is_not_taken():
    """fra233-2025-pboon's case (session 17): the lag beside the delay decisive and at 5 of
    the refit's errors, but on a residual whose correlation widens the errors 8 x: at 0.6 of
    the error the model would print it is not determined, and not taken (its held-out runs
    all got worse). The same pair on white residuals is taken."""
    from types import SimpleNamespace

    from pmdcid.diagnose.lag import _pair

    delay_free, both_free = ["J", "bv", "delay"], ["J", "bv", "delay", "tau_e", "ke_share"]
    ref = _outcome(480957.0, delay=(4e-3, 1e-5))
    both = _outcome(470000.0, delay=(4e-3, 1e-5), tau_e=(5e-5, 1e-5))
    white = _Run({frozenset(delay_free): 100.0, frozenset(both_free): 60.0})
    assert _pair(white, ref, delay_free, both, both_free, min_z=3.0)[1] == pytest.approx(-40.0)
    correlated = _Run({frozenset(delay_free): 100.0, frozenset(both_free): 60.0})
    correlated.correlated_stderr = lambda vals, free, rel=1e-2: ({}, SimpleNamespace(inflation=8.0))
    dbic, held = _pair(correlated, ref, delay_free, both, both_free, min_z=3.0)
    assert dbic < -10 and held == 0.0


def test_a_pair_whose_lag_has_a_wide_correlated_error_of_its_own_is_not_taken():
    """fra233-2025-pboon again (session 37): the largest inflation over the parameters was 7.9,
    the lag's own correlated error 47 times its white one (3.4 ms, 1.7e-5 -> 7.9e-4 s). Widened
    by the inflation alone it passed at 25 errors, and chirp_100000 rose 0.137 -> 0.145; by its
    own sandwich error, 4.3: not determined, not taken."""
    from types import SimpleNamespace

    from pmdcid.diagnose.lag import _pair

    delay_free, both_free = ["J", "bv", "delay"], ["J", "bv", "delay", "tau_e", "ke_share"]
    ref = _outcome(480957.0, delay=(4e-3, 1e-5))
    both = _outcome(470000.0, delay=(4e-3, 1e-5), tau_e=(3.4e-3, 1.7e-5))
    run = _Run({frozenset(delay_free): 100.0, frozenset(both_free): 60.0})
    run.correlated_stderr = lambda vals, free, rel=1e-2: (
        {"tau_e": 7.9e-4}, SimpleNamespace(inflation=7.9))
    dbic, held = _pair(run, ref, delay_free, both, both_free, min_z=5.0)
    assert dbic < -10 and held == 0.0
    run.correlated_stderr = lambda vals, free, rel=1e-2: (
        {"tau_e": 1.0e-4}, SimpleNamespace(inflation=7.9))
    assert _pair(run, ref, delay_free, both, both_free, min_z=5.0)[1] == pytest.approx(-40.0)

def test_a_latency_of_whole_samples_yields_to_the_lag_only_where_it_fits_decisively_better():
    """The 2025 kit's case (fra233-2025-pboon: an 11 ms USB latency, a lag fitting its fit logs
    0.08 % better on a residual correlated over 236 samples; the held-out chirps rose 0.20 ->
    0.22 when the lag replaced it): decisive by the rules' BIC on the residual's effective
    samples, not on every sample."""
    from types import SimpleNamespace

    from pmdcid.diagnose.lag import _decisive_latency_free

    final, lag = _outcome(4568590.0), _outcome(4564851.0)
    for tau_int, decisive in ((236.0, False), (0.5, True)):
        run = _Run({})
        run.correlated_stderr = lambda vals, free, t=tau_int: ({}, SimpleNamespace(tau_int=t))
        run.count = lambda part: 62000
        assert _decisive_latency_free(run, final, ["J"], lag) is decisive


@pytest.mark.slow
def test_a_model_delay_refitted_to_nothing_ends_with_a_note(tmp_path):
    """fit-mechanical's latency standing in for a speed sensor's bias (bench/thinlogs.py
    b2:speed_offset seed 14: 20 ms, no delay in the truth), refitted by diagnose to under a
    tenth of a sample beside the bias it found: no lag shorter than it to try beside it. At
    main 471418b: "internal error ValueError: min() arg is an empty sequence"."""
    fit, _, _, _, _ = scenario("b2:speed_offset", 14)
    paths = [write(tmp_path, *x) for x in fit]
    res = identify(paths, diagnose=True, progress=False,
                   mapping=parse_mapping(["omega=speed_rpm*rpm"]))
    assert "speed_offset" in res.model.effects


@pytest.mark.slow
def test_a_lag_whose_share_the_logs_do_not_tell_replaces_the_delay():
    """bench/lawlag.py's share03 motor (back-EMF about 0.3 of the per-volt damping, 500 Hz,
    L/R 2 ms, seed 2, no delay): the lag in the delay's place fits 32 chi-square units better,
    but its tau_e was 0.73 standard errors: the marginal error, inflated by a share the logs do
    not tell (shares 0 to 1 fit as well), and the delay was kept (J' -8 standard errors). With
    the share held tau_e is determined: no delay is written, J' and tau_e cover the truth,
    and the share, whose +-2 standard errors span all of 0 to 1, is written without one, in
    words (its error was 0.58 about 1e-4: docs/identification.md)."""
    from bench.lawlag import per_volt
    from bench.lawlag import scenario as lawlag_scenario

    fit, _, vals = lawlag_scenario(2, 2.0, 500.0, "none", "share03")
    model = identify(fit, diagnose=True, progress=False).model
    assert "sensor_delay" not in model.effects, model.effects
    true = per_volt(vals)
    for k in ("J", "tau_e"):
        p = model.parameters[k]
        assert abs(p.value - true[k]) <= 2.0 * p.stderr, (k, p.value, p.stderr, true[k])
    share = model.parameters["ke_share"]
    # written without a standard error, in words (bounded only by its range, or at its bound)
    assert math.isnan(share.stderr) and share.caveat.startswith("not determined by these logs")
