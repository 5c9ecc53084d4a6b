"""diagnose's final refits (pmdcid/diagnose/final.py): what they free."""

from __future__ import annotations

from types import SimpleNamespace

from pmdcid.diagnose.final import free_of, lag_left_open
from pmdcid.fit.results import Estimate
from pmdcid.model import Model


def _run(tau_e: float):
    return SimpleNamespace(base_free=["J", "bv", "bc", "dz"], vals0={"tau_e": tau_e})


def test_a_lumped_lag_is_refitted_with_the_added_effects():
    """A lumped model with an electrical lag: tau_e and ke_share are free in the final refits
    once an effect is added (the share sets where the dead zone acts; held, dz took up the
    difference: bench/pervolt_coverage.py --diagnose, dz +5.9 % -> +2.1 %)."""
    assert free_of(_run(3e-3), ["quadratic_drag"]) == ["J", "bv", "bc", "dz", "bq", "tau_e",
                                                        "ke_share"]


def test_no_lag_or_nothing_added_frees_no_lag():
    assert free_of(_run(0.0), ["quadratic_drag"]) == ["J", "bv", "bc", "dz", "bq"]
    assert free_of(_run(3e-3), []) == ["J", "bv", "bc", "dz"]


def _instant_model() -> Model:
    """A lumped model with an instant current: tau_e 0 in [0, 5 ms], a share, J's standard
    error widened to reach the fit with the lag at that bound (identify/instant.py)."""
    m = Model()
    m.set_bounded("tau_e", 0.0, 5e-3, 0.0)
    m.set("ke_share", 0.9, 0.01)
    m.set("J", 1e-3, 1e-4)
    m.set("bc", 0.3, 0.01)
    return m


def test_a_refit_without_the_lag_keeps_the_errors_that_reach_it():
    """diagnose's final refit holds tau_e at 0: its errors say how well the model fits there,
    not where the lag the steps left open puts it. J's is kept at the model's (wider); bc's,
    wider already, stays; the note names J."""
    run = SimpleNamespace(model=_instant_model())
    final = SimpleNamespace(values={"J": 1.01e-3, "bc": 0.31, "tau_e": 0.0},
                            estimates={"J": Estimate("J", 1.01e-3, 1e-5),
                                       "bc": Estimate("bc", 0.31, 0.05)})
    notes = []
    lag_left_open(run, final, ["J", "bc"], notes)
    assert final.estimates["J"].stderr == 1e-4 and final.estimates["J"].value == 1.01e-3
    assert final.estimates["bc"].stderr == 0.05
    assert len(notes) == 1 and notes[0].startswith("J:") and "5 ms" in notes[0]


def test_a_refit_that_took_the_lag_keeps_its_own_errors():
    """Where diagnose took the lag (tau_e > 0) the lag is no longer left open: nothing kept."""
    run = SimpleNamespace(model=_instant_model())
    final = SimpleNamespace(values={"J": 1e-3, "tau_e": 2e-3},
                            estimates={"J": Estimate("J", 1e-3, 1e-5)})
    notes = []
    lag_left_open(run, final, ["J"], notes)
    assert final.estimates["J"].stderr == 1e-5 and not notes

