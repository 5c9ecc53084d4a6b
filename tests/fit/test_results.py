"""fit/results.py: the NRMSE where it is undefined, and how a table says so."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pmdcid.fit.results import (
    NRMSE_UNDEFINED,
    Estimate,
    FitStats,
    SimFitResult,
    bounded,
    correlations,
    nrmse,
    nrmse_text,
)
from pmdcid.model import Model, load_model


def test_nrmse_of_a_measurement_that_never_changes_is_undefined(rng):
    """A speed logged as exact zeros (a stalled or unplugged sensor): std 0, so RMS/std has no
    value; NaN, and a table says it in words, never ``inf``."""
    sim = rng.normal(0.0, 0.1, 500)
    value = nrmse(sim, np.zeros(500))
    assert math.isnan(value)
    assert nrmse_text(value) == NRMSE_UNDEFINED
    assert "inf" not in nrmse_text(math.inf) and "nan" not in nrmse_text(value)


def test_nrmse_text_of_a_number(rng):
    meas = rng.normal(0.0, 1.0, 2000)
    value = nrmse(meas + rng.normal(0.0, 0.1, 2000), meas)
    assert 0.08 < value < 0.12
    assert nrmse_text(value) == f"{value:.4f}"


def test_correlations_of_a_covariance_that_is_not_psd():
    """A degenerate third column (its variance a rounding's 1e-30, its covariances with the
    others of the others' size, as a non-PSD sum leaves them): its raw correlations are ~1e7;
    :func:`correlations` gives it a NaN row and keeps the determined pair exactly."""
    sd = np.array([2.0, 0.5])
    r01 = -0.6
    cov = np.array([[sd[0] ** 2, r01 * sd[0] * sd[1], 0.9],
                    [r01 * sd[0] * sd[1], sd[1] ** 2, -0.2],
                    [0.9, -0.2, 1e-30]])
    r = correlations(cov)
    assert r[0, 1] == pytest.approx(r01) and r[1, 0] == pytest.approx(r01)
    assert np.isnan(r[2]).all() and np.isnan(r[:, 2]).all()
    assert np.nanmax(np.abs(r)) <= 1.0


def test_correlations_zero_or_negative_variance_and_rounding():
    """A zero and a negative variance are degenerate (NaN rows); 1 + 1e-12 is rounding, clipped."""
    cov = np.array([[1.0, 1.0 + 1e-12, 0.3, 0.1], [1.0 + 1e-12, 1.0, 0.2, 0.1],
                    [0.3, 0.2, 0.0, 0.0], [0.1, 0.1, 0.0, -1e-8]])
    r = correlations(cov)
    assert r[0, 1] == 1.0 and r[0, 0] == 1.0
    assert np.isnan(r[2]).all() and np.isnan(r[3]).all()


def test_sim_fit_result_correl_within_unit_interval():
    """A result built with a correlation of 9 (a non-PSD covariance's) says NaN, not 9."""
    est = {n: Estimate(n, 1.0, 0.1, "") for n in ("J", "bc")}
    stats = FitStats(100, 2, 98.0, 5, True, "")
    res = SimFitResult(est, stats, {"J": {"bc": 9.0}, "bc": {"J": -0.5}})
    assert math.isnan(res.correlation("J", "bc")) and res.correlation("bc", "J") == -0.5



def test_an_error_spanning_the_whole_range_is_shown_in_words():
    """A share fitted 1e-4 ± 0.58 (its +-2 se cover [0, 1]): kept for the readings that follow
    the cost, printed and tabled without a ±, the words in its place."""
    from pmdcid.fit.results import fitted, format_estimates, shown

    e = fitted("ke_share", 1e-4, 0.58, "1")
    assert e.stderr == 0.58  # the number the share's valley reads
    s = shown(e)
    assert math.isnan(s.stderr) and "bounded only by its range [0, 1]" in s.caveat
    assert "±" not in str(e) and "bounded only by its range" in str(e)
    line = format_estimates([e])[1]
    assert "0.58" not in line and "bounded only by its range" in line
    from pmdcid.fit.results import ResultProtocol

    res = ResultProtocol()
    res.estimates = {"ke_share": e}
    assert math.isnan(res.rows()[0][2])  # to_dict, to_pandas, the notebook's table
    assert shown(fitted("ke_share", 0.9, 0.2, "1")).stderr == 0.2  # [0.5, 1.3]: it says something
    assert shown(fitted("J", 1.0, 10.0, "kg m^2")).stderr == 10.0  # an open range


def test_a_speed_that_runs_against_the_model_on_every_log_is_said(rng):
    """A sensor counting the other way gives a correlation near -1 on every log; one log that
    follows the model, or a speed that never moves, says nothing."""
    from pmdcid.fit.results import speed_against

    t = np.linspace(0, 4, 400)
    sim = 50 * np.sin(t)
    meas = -sim + rng.normal(0, 2, t.size)
    line = speed_against([(sim, meas), (2 * sim, 2 * meas)])
    assert line and "-c omega=COLUMN*-1" in line and "-1.00" in line
    assert speed_against([(sim, meas), (sim, sim + rng.normal(0, 2, t.size))]) is None
    assert speed_against([(sim, np.zeros_like(sim))]) is None
    assert speed_against([]) is None



def test_an_estimate_the_logs_do_not_determine_leaves_what_other_data_determined():
    """fuzzing: fit-nonlinear on a log whose input stayed at 0 while the rotor turned wrote bv
    and bc 'not determined' (no variance) over fit-mechanical's estimates. Such an estimate
    leaves a value another stage determined; it is written where the model has none, or only
    a start value or an interval."""
    from pmdcid.fit.results import fitted, write_estimate
    from pmdcid.model import Model

    m = Model()
    m.set("bv", 0.01, 1e-4, stage="fit-mechanical")
    m.set("J", 1e-3, stage="start")  # a start value: no data determined it
    undetermined = fitted("bv", 0.5, math.nan, "N m s/rad")
    write_estimate(m, undetermined, "fit-nonlinear")
    assert (m.value("bv"), m.parameters["bv"].stage) == (0.01, "fit-mechanical")
    write_estimate(m, fitted("J", 2e-3, math.nan, "kg m^2"), "fit-nonlinear")
    assert m.value("J") == 2e-3 and m.parameters["J"].stage == "fit-nonlinear"
    write_estimate(m, fitted("bc", 0.2, math.nan, "N m"), "fit-nonlinear")
    assert m.value("bc") == 0.2  # none before
    write_estimate(m, fitted("bv", 0.02, 2e-4, "N m s/rad"), "fit-nonlinear")
    assert m.value("bv") == 0.02  # determined here: written


def _motor_logs(rng):
    """A blocked-rotor step and a free step of one SI motor, simulated by pmdcid with noise."""
    import pmdcid
    from pmdcid.model import Model
    from pmdcid.simulate import blocked_rotor, param_values, simulate_values

    truth = Model()
    for k, v in dict(R=2.0, L=4e-3, km=0.05, J=2e-5, bv=1e-5, bc=2e-3, dz=0.0).items():
        truth.set(k, v)
    t = np.arange(3000) * 1e-3
    v = np.where(t >= 0.1, 3.0, 0.0)
    vals = param_values(truth)
    free = simulate_values(t, v, vals)
    held = simulate_values(t[:400], v[:400], blocked_rotor(vals))
    blocked = pmdcid.Log.from_arrays(t[:400], v=v[:400],
                                     i=held.i + rng.normal(0, 5e-3, 400), name="blocked")
    step = pmdcid.Log.from_arrays(t, v=v, i=free.i + rng.normal(0, 5e-3, t.size),
                                  omega=free.omega + rng.normal(0, 0.05, t.size), name="step")
    return truth, blocked, step


def test_a_stage_result_plots_its_fitted_model_beside_each_log(rng):
    """``result.plot()`` (as lmfit's): one panel per log the result was fitted on, the
    measurement and the simulation of the model the result makes (the model it was fitted
    from, the result applied) from the log's measured start; a log the model cannot simulate
    yet is named under the figure, not drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import pmdcid
    from pmdcid.simulate.measured import simulate_for

    truth, blocked, step = _motor_logs(rng)
    start = truth.copy()
    start.set("J", 3e-5)
    res = pmdcid.fit_nonlinear([step], start, free=["J"], priors=False)
    fitted = res.fitted_model()
    assert fitted.value("J") == res.estimates["J"].value != start.value("J")
    fig = res.plot()
    (ax,) = fig.axes
    meas, model = (line.get_ydata() for line in ax.lines)
    np.testing.assert_array_equal(meas, step["omega"])
    np.testing.assert_array_equal(model, simulate_for(step, fitted).omega)
    assert "NRMSE" in ax.get_title()
    plt.close(fig)
    elec = pmdcid.fit_electrical([blocked])  # R, L alone: the held rotor's current is drawn
    fig = elec.plot([blocked, step])
    assert len(fig.axes) == 1 and any("not drawn: step" in x.get_text() for x in fig.texts)
    np.testing.assert_array_equal(fig.axes[0].lines[0].get_ydata(), blocked["i"])
    plt.close(fig)


def test_a_result_without_its_logs_says_what_to_give():
    from pmdcid.errors import PmdcidError
    from pmdcid.identify.linstart import LinearStart

    res = LinearStart.__new__(LinearStart)
    with pytest.raises(PmdcidError, match=r"give them, result.plot\(logs\)"):
        res.plot()


def test_a_bound_wider_than_the_parameters_range_is_cut_to_it(tmp_path):
    """A bound the logs leave wider than physics (tau_e below 9 s, a share above 1) is written
    as the parameter's own range, which a model file can hold and load again."""
    lag = bounded("tau_e", 0.0, 9.06, "s", "open", value=0.0)
    share = bounded("ke_share", -0.2, 1.7, "1", "open")
    assert lag.interval == (0.0, 1.0) and lag.value == 0.0
    assert share.interval == (0.0, 1.0) and share.value == pytest.approx(0.5)
    model = Model()
    for e in (lag, share):
        model.set_bounded(e.name, *e.interval, e.value, unit=e.unit, stage="test", caveat="x")
    model.save(tmp_path / "m.json")
    assert load_model(tmp_path / "m.json").parameters["tau_e"].interval == (0.0, 1.0)
