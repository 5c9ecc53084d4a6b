"""The report's faster figures: min/max envelope decimation and reused figures (issue #16).

Decimation changes what is drawn, never what is computed: each pixel column keeps its extremes
(spikes survive), short lines and NaN gaps are drawn as they are, and a figure reused from the
pool draws the same pixels as a new one.
"""

import io

import numpy as np
import pytest

from pmdcid.io import read_log, write_log
from pmdcid.report import figures
from pmdcid.report.compare import compare_log
from pmdcid.report.decimate import (
    POINTS_PER_COLUMN,
    SCATTER_POINTS,
    envelope_indices,
    pixel_bins,
    scatter_indices,
)
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, triangle, truth_model


def _bin_extremes(y, bins, columns):
    lo = np.full(columns, np.inf)
    hi = np.full(columns, -np.inf)
    ok = ~np.isnan(y)
    np.minimum.at(lo, bins[ok], y[ok])
    np.maximum.at(hi, bins[ok], y[ok])
    return lo, hi


def _stick_slip(rng, n=120_000):
    """A noisy signal with plateaus at zero, steps and single-sample spikes."""
    t = np.arange(n) * 1e-3
    y = np.sin(2 * np.pi * t / 40) + 0.01 * rng.standard_normal(n)
    y[np.abs(y) < 0.3] = 0.0  # stick: plateaus
    y[n // 3:] += 0.5  # a step
    spikes = rng.choice(n, 7, replace=False)
    y[spikes] += rng.choice([-3.0, 3.0], 7)
    return t, y, spikes


@pytest.mark.parametrize("columns", [1000, 357, 1])
def test_envelope_keeps_every_pixel_bins_min_max_first_and_last(rng, columns):
    t, y, spikes = _stick_slip(rng)
    k = envelope_indices(t, y, columns)
    assert len(k) <= 4 * columns and np.all(np.diff(k) > 0)  # subset, in time order
    bins = pixel_bins(t, columns)
    full = _bin_extremes(y, bins, columns)
    kept = _bin_extremes(y[k], bins[k], columns)
    np.testing.assert_array_equal(kept[0], full[0])
    np.testing.assert_array_equal(kept[1], full[1])
    # a one-sample spike is never dropped when it is its pixel column's extreme
    tops = [s for s in spikes if y[s] in (full[0][bins[s]], full[1][bins[s]])]
    assert len(tops) >= (len(spikes) if columns > 1 else 1)
    assert set(tops) <= set(k.tolist())
    firsts = np.flatnonzero(np.r_[True, np.diff(bins) != 0])
    lasts = np.r_[firsts[1:] - 1, len(y) - 1]
    assert set(firsts) <= set(k.tolist()) and set(lasts) <= set(k.tolist())


def test_envelope_bins_are_equal_in_time_when_sampling_is_uneven(rng):
    # a fast burst then slow sampling: bins follow time, so each column still shows its extremes
    t = np.r_[np.linspace(0, 1, 90_000, endpoint=False), np.linspace(1, 10, 10_000)]
    y = rng.standard_normal(len(t))
    k = envelope_indices(t, y, 500)
    bins = pixel_bins(t, 500)
    assert bins[90_000] == 50  # t = 1 s is a tenth of the way
    full, kept = _bin_extremes(y, bins, 500), _bin_extremes(y[k], bins[k], 500)
    np.testing.assert_array_equal(kept[0], full[0])
    np.testing.assert_array_equal(kept[1], full[1])


def test_short_line_is_drawn_unchanged(rng):
    n = POINTS_PER_COLUMN * 800
    t, y = np.arange(n) * 1e-3, rng.standard_normal(n)
    np.testing.assert_array_equal(envelope_indices(t, y, 800), np.arange(n))
    assert len(envelope_indices(t[:1], y[:1], 800)) == 1
    assert len(envelope_indices(t, y, 799)) < n  # one column fewer: decimated


def test_nan_samples_stay_gaps(rng):
    t, y, _ = _stick_slip(rng)
    y[50_000:50_005] = np.nan  # a dropout inside one bin
    y[80_000:81_000] = np.nan  # a dropout over whole bins
    k = envelope_indices(t, y, 1000)
    bins = pixel_bins(t, 1000)
    with_nan = np.unique(bins[np.isnan(y)])
    assert set(with_nan) == set(np.unique(bins[k][np.isnan(y[k])]))
    full, kept = _bin_extremes(y, bins, 1000), _bin_extremes(y[k], bins[k], 1000)
    np.testing.assert_array_equal(kept[0], full[0])
    np.testing.assert_array_equal(kept[1], full[1])


def test_scatter_keeps_the_cloud_and_its_outliers(rng):
    n = 120_000
    e = rng.standard_normal(n)
    e[[1234, 98_765]] = [9.0, -7.0]  # two outliers a uniform sample would miss
    e[5000:5010] = np.nan
    k = scatter_indices(e)
    assert {1234, 98_765} <= set(k.tolist())
    assert np.nanmax(e[k]) == 9.0 and np.nanmin(e[k]) == -7.0
    assert len(k) < 1.1 * SCATTER_POINTS  # a sample, plus the few points beyond its range
    # the density survives: the drawn cloud has the spread of the full one (an envelope of
    # each pixel column's extremes would give about 3x the standard deviation)
    assert np.nanstd(e[k]) == pytest.approx(np.nanstd(e), rel=0.1)
    short = rng.standard_normal(2 * SCATTER_POINTS)
    np.testing.assert_array_equal(scatter_indices(short), np.arange(len(short)))


# ---- figures -------------------------------------------------------------------------------

def _log(tmp_path, rng, name, n, amp, blocked=False, spike=None):
    t = np.arange(n) * 1e-3
    u = np.full(n, amp) if blocked else triangle(t, amp, n * 1e-3 / 2)
    cols, _ = synth_log(t, u, {**neutral_values(), **PAPER}, PAPER_NOISE, rng, blocked=blocked)
    if spike is not None:
        cols["omega"][spike] += 5.0
    write_log(tmp_path / name, t, cols, {"kind": "blocked" if blocked else "triangle"})
    return compare_log(read_log(tmp_path / name), truth_model(PAPER), name[:-4])


def _pixels(png: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(png)))


@pytest.mark.slow  # a round trip of seconds: make test, not test-fast
def test_reused_figures_draw_the_same_pixels_as_new_ones(tmp_path, rng):
    cmps = [_log(tmp_path, rng, "long.csv", 60_000, 2.0),
            _log(tmp_path, rng, "blocked.csv", 1500, 1.0, blocked=True),
            _log(tmp_path, rng, "short.csv", 3000, 0.7)]
    pool = figures.FigurePool()
    for c in cmps + cmps[::-1]:  # every layout reused after a different log
        for draw in (figures.overlay_figure, figures.residual_figure):
            fresh, pooled = _pixels(draw(c)), _pixels(draw(c, pool))
            assert fresh.shape == pooled.shape
            assert np.array_equal(fresh, pooled), (c.name, draw.__name__)


def test_overlay_draws_a_one_sample_spike_of_a_long_log(tmp_path, rng):
    c = _log(tmp_path, rng, "spiky.csv", 120_000, 2.0, spike=77_777)
    pool = figures.FigurePool()
    figures.overlay_figure(c, pool)
    (fig, axes), = pool._figs.values()
    line = axes[1, 0].lines[0]  # measured speed, full length (the input is on top)
    drawn = np.asarray(line.get_ydata())
    assert len(drawn) < c.log.n // 10  # decimated ...
    assert drawn.max() == np.nanmax(c.log["omega"])  # ... but the spike is drawn
    assert drawn.min() == np.nanmin(c.log["omega"])
