"""diagnose's final refits (pmdcid/diagnose/final.py): what they free."""

from __future__ import annotations

from types import SimpleNamespace

from pmdcid.diagnose.final import free_of


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
