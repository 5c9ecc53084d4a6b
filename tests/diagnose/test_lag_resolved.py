"""A lag taken in a sensor delay's place must be determined by the logs (diagnose/lawlag.py's
``lag_resolved``): issue 24, "diagnose never raises any held-out log's error by more than 5 %".

Round trip on ``bench/newrigs.py``'s LEGO-like rig (seed 2 of ``default_rng``): a geared motor,
duty steps of +-30/60/90 % logged loop-timed 4-18 ms apart (resampled to about 11 ms), the angle
alone in whole degrees, 2 degrees of gear backlash; held out: sines. Its L/R (0.75 ms) is a
fifteenth of a sample. Main at f14047c took a sensor delay's place with a lag of 4.6 +- 4.6 ms
whose back-EMF share went to 0.04 +- 9 (0.98) and moved the masked dead zone to 1.38 V on the
lagged voltage: every held-out sine rose through diagnose (0.018 -> 0.033 on one). Seed 1:
main at 8c325d5 took a sensor delay the cross-log folds bore out but whose refit raised the
speed error on the time split's held-out parts 13 % (diagnose/candidates.py ``across_logs``),
then the lag in its place: both held-out sines rose 0.033 -> 0.038.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from bench.closedloop_redteam import read_mapped
from bench.newrigs import lego, write
from bench.realdata import predict
from pmdcid.api import diagnose, identify
from pmdcid.diagnose.lawlag import lag_resolved, lag_z
from pmdcid.fit.problem import FitOutcome
from pmdcid.fit.results import Estimate

#: issue 24's bound on a held-out log's rise through diagnose
MAX_RISE = 0.05


def _outcome(value: float, stderr: float) -> FitOutcome:
    return FitOutcome({"tau_e": value}, {"tau_e": Estimate("tau_e", value, stderr, "s")}, None)


def test_a_lag_within_its_standard_errors_of_zero_is_not_resolved():
    assert lag_z(_outcome(4.6e-3, 4.6e-3)) == pytest.approx(1.0)
    assert not lag_resolved(_outcome(4.6e-3, 4.6e-3), 5.0)
    assert lag_resolved(_outcome(4.7e-3, 0.6e-3), 5.0)
    assert not lag_resolved(_outcome(4.7e-3, math.nan), 5.0)  # no error: nothing determined
    assert not lag_resolved(_outcome(math.nan, math.nan), 5.0)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_diagnose_raises_no_held_out_sine_on_a_loop_timed_lego_rig(tmp_path, seed):
    rig = lego(seed)
    fit = [read_mapped(p, rig.maps) for p in write(tmp_path, rig.steps)]
    held = [read_mapped(p, rig.maps)
            for p in write(tmp_path, [r for runs in rig.held.values() for r in runs])]
    before = identify(fit, diagnose=False, progress=False).model
    after = diagnose(fit, before, progress=False).model
    errs = np.array([(predict(before, lg), predict(after, lg)) for lg in held])
    assert np.all(errs[:, 1] <= (1 + MAX_RISE) * errs[:, 0]), errs
    if after.has("tau_e"):  # a lag diagnose writes is one the logs determine
        par = after.parameters["tau_e"]
        assert par.value >= 5.0 * par.stderr, (par.value, par.stderr)


def test_a_lag_along_an_untold_share_is_judged_with_the_share_held():
    """tau_e 2.05 +- 2.8 ms (0.73 standard errors: bench/lawlag.py share03, seed 2) whose
    error is almost all along the share's valley (local correlation 0.999): with the share
    held, sqrt(1 - 0.999^2) of it, the lag is determined; without a correlation, it is not."""
    fo = _outcome(2.05e-3, 2.8e-3)
    assert not lag_resolved(fo, 5.0)
    assert lag_z(fo, 0.999) == pytest.approx(2.05 / (2.8 * math.sqrt(1 - 0.999 ** 2)))
    assert lag_resolved(fo, 5.0, 0.999)
    assert not lag_resolved(fo, 5.0, 0.5)


def test_a_sub_sample_lag_leaves_a_dead_zone_the_samples_did_not_show_masked():
    """diagnose/final.py ``sub_sample_masked``: with the lag diagnose took under a sample, a
    dead zone the earlier fit found masked keeps that interval; a lag of a sample or more, a
    dead zone the samples showed (no interval), an effect added, or no lag taken: the refit
    reads it as before."""
    from types import SimpleNamespace

    from pmdcid.diagnose.final import sub_sample_masked
    from pmdcid.model import Model

    model = Model()
    model.set_bounded("dz", 0.0, 1.03, 0.51, unit="V")
    run = SimpleNamespace(model=model, lag_taken=True,
                          problem=SimpleNamespace(logs=[SimpleNamespace(dt=0.011),
                                                        SimpleNamespace(dt=0.012)]))
    free = ["J", "bv", "bc", "dz", "tau_e", "ke_share"]
    final = SimpleNamespace(values={"tau_e": 2.5e-3})
    assert sub_sample_masked(run, final, free) == pytest.approx(1.03)
    assert sub_sample_masked(run, SimpleNamespace(values={"tau_e": 0.011}), free) is None
    assert sub_sample_masked(run, final, [p for p in free if p != "dz"]) is None
    assert sub_sample_masked(run, final, [*free, "dbv"]) is None  # an effect added
    assert sub_sample_masked(SimpleNamespace(**{**vars(run), "lag_taken": False}), final,
                             free) is None
    seen = Model()
    seen.set("dz", 0.51, 0.05, "V")
    assert sub_sample_masked(SimpleNamespace(**{**vars(run), "model": seen}), final,
                             free) is None


@pytest.mark.slow
def test_identify_keeps_the_masked_dead_zone_through_a_sub_sample_lag(tmp_path):
    """LEGO-like rig seed 6 through ``identify`` with diagnose: the lag taken (about 2.5 ms on
    an 11 ms grid; L/R 0.7 ms, 2 degrees of backlash) moved the masked dead zone (0 to 1.03 V,
    the model's 0.51) to 1.81 +- 0.44 V, read from starts from rest delayed by a fraction of a
    sample, and the held-out sines rose 0.019 -> 0.047. The interval is kept now. (Since its
    duty steps, applied at the first sample, are read as steps by fit-mechanical, the lag comes
    from the steps and diagnose no longer meets the case through identify: the held-out sines
    and the interval are asserted here, sub_sample_masked's note by the test above.)"""
    rig = lego(6)
    fit = [read_mapped(p, rig.maps) for p in write(tmp_path, rig.steps)]
    held = [read_mapped(p, rig.maps)
            for p in write(tmp_path, [r for runs in rig.held.values() for r in runs])]
    before = identify(fit, diagnose=False, progress=False).model
    res = identify(fit, progress=False)
    errs = np.array([(predict(before, lg), predict(res.model, lg)) for lg in held])
    assert np.all(errs[:, 1] <= (1 + MAX_RISE) * errs[:, 0]), errs
    dz = res.model.parameters["dz"]
    assert dz.interval is not None and dz.value == pytest.approx(before.value("dz"))
