"""diagnose's weighted residual per part (fit, held-out, all) selects each channel's samples
once (as a slice where evenly spaced): the same numbers as residual-then-mask."""

from __future__ import annotations

import numpy as np
import pytest
from repo_paths import FIXTURES

from pmdcid.fit.problem import Problem, as_slice
from pmdcid.io import read_log
from pmdcid.simulate import param_values
from pmdcid.synth import truth_model

HIDDEN = FIXTURES / "hidden"


def test_as_slice_selects_the_same_samples(rng):
    x = rng.normal(size=1000)
    for idx in (np.arange(0, 1000, 6), np.arange(3, 700, 6), np.arange(5, 6), np.arange(0),
                np.array([0, 1, 5, 9]), np.array([2, 4, 6, 9])):
        np.testing.assert_array_equal(x[as_slice(idx)], x[idx])
    assert isinstance(as_slice(np.arange(0, 1000, 6)), slice)


def test_channels_keep_no_index_or_copy_of_the_log_length():
    """Every sample compared (a simulation-error fit): the channel's samples are a slice and its
    measured values the log's own column, no array of the log's length is added (the 2 M-row
    fit's peak memory); strided (diagnose): a compact copy, not a view holding the column."""
    log = read_log(HIDDEN / "triangle.csv")
    (every,) = Problem([log], max_samples=None, plan=["fit"], signals=("omega",)).channels
    assert every.rows == slice(0, log.n, 1)
    assert np.shares_memory(every.meas, np.asarray(log["omega"], float))
    (strided,) = Problem([log], max_samples=1000, plan=["fit"], signals=("omega",)).channels
    stride = -(-log.n // 1000)
    assert stride > 1 and strided.rows == slice(0, log.n, stride)
    assert strided.meas.flags.c_contiguous and strided.meas.base is None
    np.testing.assert_array_equal(strided.meas, np.asarray(log["omega"], float)[::stride])


@pytest.mark.parametrize("plan", [None, ["fit", "held", "split", "split", "held", "fit"]])
def test_weighted_parts_match_residual_then_mask(plan):
    logs = [read_log(p) for p in sorted(HIDDEN.glob("step_*.csv"))]
    logs.append(read_log(HIDDEN / "triangle.csv"))
    pr = Problem(logs, plan=plan)
    vals = {**param_values(truth_model({"R": 2.37, "L": 0.0178, "km": 0.0502, "J": 3.1e-3,
                                        "bv": 0.031, "bc": 0.005, "dz": 0.006}))}
    sims = pr.simulate_all(vals)
    for part in ("fit", "held", "all"):
        ref = []
        for ch in pr.channels:
            r = pr.residual(sims, ch) / ch.sigma
            r = np.where(np.isfinite(r), r, 0.0)
            ref.append(r if part == "all" else r[ch.fit] if part == "fit" else r[~ch.fit])
        ref = np.concatenate(ref)
        got = pr.weighted(sims, part)
        assert len(got) == pr.count(part) > 0
        assert got.tobytes() == ref.tobytes()
    # the simulations were not written into by the in-place arithmetic
    again = pr.simulate_all(vals)
    for a, b in zip(sims, again, strict=True):
        np.testing.assert_array_equal(a.omega, b.omega)


@pytest.mark.parametrize("plan", [None, ["fit", "held", "split", "split", "held", "fit", "split"]])
@pytest.mark.parametrize("extra", [{}, {"delay": 4e-3, "latency": 3e-3, "omega0": 0.05},
                                   {"ramp": 0.5, "latency": 3e-3}])
@pytest.mark.slow  # a round trip of seconds: make test, not test-fast
def test_each_part_simulated_only_as_far_as_it_needs(plan, extra, tmp_path):
    """The fit part's simulations stop at its last compared sample (a log held out whole is
    not simulated): the kernel, a late input or one read between samples (``ramp``) and a
    delayed sensor are causal, so the residual
    is the same to the bit; a speed derived from the angle (zero-phase filter) is simulated
    whole."""
    import pandas as pd

    logs = [read_log(p) for p in sorted(HIDDEN.glob("step_*.csv"))]
    logs.append(read_log(HIDDEN / "triangle.csv"))
    tri = pd.read_csv(HIDDEN / "triangle.csv", comment="#")
    tri.drop(columns=["omega"]).to_csv(tmp_path / "angle_only.csv", index=False)
    logs.append(read_log(tmp_path / "angle_only.csv"))
    assert "omega" in logs[-1].derived
    pr = Problem(logs, plan=plan)
    vals = {**param_values(truth_model({"R": 2.37, "L": 0.0178, "km": 0.0502, "J": 3.1e-3,
                                        "bv": 0.031, "bc": 0.005, "dz": 0.006})), **extra}
    whole = pr.simulate_all(vals)
    chi2 = pr.chi2(vals)
    for part in ("fit", "held", "all"):
        short = pr.simulate_all(vals, part)
        assert pr.weighted(short, part).tobytes() == pr.weighted(whole, part).tobytes()
        assert pr.cost(vals, part) == chi2[part]
    fit_plan = plan or ["split"] * len(logs)
    for k, (sim, p) in enumerate(zip(pr.simulate_all(vals, "fit"), fit_plan, strict=True)):
        if p == "held":
            assert sim is None
        elif k == len(logs) - 1:
            assert len(sim.t) == logs[k].n  # a derived speed: simulated whole
        elif p == "split":
            assert len(sim.t) < 0.65 * logs[k].n  # the first 60 % and a stride
        else:
            assert len(sim.t) > 0.99 * logs[k].n  # fitted whole: up to its last compared sample
