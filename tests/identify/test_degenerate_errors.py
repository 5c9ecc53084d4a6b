"""A variance the logs leave at zero or below is no standard error in the stages' own
propagated errors either (issue 24, Build 3: the scalar clips ``sqrt(max(var, 0))`` printed
± 0, a parameter known exactly): each code path with a constructed degenerate covariance."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from pmdcid.fit.results import NOT_DETERMINED
from pmdcid.identify import mechsteps
from pmdcid.identify.freerun import _offsets
from pmdcid.identify.mechanical import line_friction
from pmdcid.plan.fisher import predicted_se


def test_steady_line_friction_from_a_singular_covariance_has_no_errors():
    """The steady-speed line's (a, c) with a covariance of zeros (one level repeated: nothing
    to tell slope from intercept): bv's and bc's errors are NaN, not 0."""
    d_eff, bv, bv_se, bc, bc_se = line_friction(50.0, -4.0, np.zeros((2, 2)), 0.05, 1.0,
                                                0.0025)
    assert d_eff == pytest.approx(0.05 / 50.0) and bc == pytest.approx(4.0 * d_eff)
    assert math.isnan(bv_se) and math.isnan(bc_se)
    cov = np.array([[0.25, -0.1], [-0.1, 0.09]])
    _, _, bv_se, _, bc_se = line_friction(50.0, -4.0, cov, 0.05, 1.0, 0.0025)
    assert bv_se == pytest.approx(d_eff * 0.5 / 50.0)
    g = np.array([-4.0 * d_eff / 50.0, -d_eff])
    assert bc_se == pytest.approx(math.sqrt(g @ cov @ g))


def test_head_level_with_a_degenerate_variance_has_no_error(monkeypatch):
    """A head whose level's variance comes out zero: its error is NaN (and the level then
    stays off the steady-speed line: not clear of its error), not 0."""
    t = np.arange(200) * 1e-3
    w = 30.0 + 5.0 * np.exp(-t / 0.05)
    log = SimpleNamespace(t=t, path="head.csv")
    step = SimpleNamespace(onset=200, before=6.0)
    h = mechsteps.head_level(log, step, w, 0.1, 0.05, math.nan)
    assert h.omega_ss == pytest.approx(30.0) and h.omega_ss_se > 0
    monkeypatch.setattr(mechsteps.np.linalg, "pinv", lambda a: np.zeros_like(a))
    h = mechsteps.head_level(log, step, w, 0.1, 0.05, math.nan)
    assert math.isnan(h.omega_ss_se)


class _Log(dict):
    """A log as ``_offsets`` reads it: a path and its columns."""

    def __init__(self, path, cols):
        super().__init__(cols)
        self.path = path


def test_free_running_offset_with_a_zero_variance_is_not_determined():
    """A log's voltage offset b/g whose propagated variance is zero: no standard error, the
    words in its place, and no warning that it is significant (at main: ± 0, "significant")."""
    log = _Log("run.csv", {"v": np.full(10, 12.0)})
    th = np.array([0.9, 0.5, 0.0, 0.0, 0.2])
    warns: list[str] = []
    out = _offsets([log], th, np.zeros((5, 5)), warns)
    e = out["run.csv"]
    assert e.value == pytest.approx(0.4)
    assert math.isnan(e.stderr) and e.caveat == NOT_DETERMINED
    assert warns == []


def test_plan_predicts_no_error_for_a_variance_not_positive():
    """plan's predicted errors by the same rule, written inf (plan's word for a parameter the
    profiles leave free), never 0."""
    se = predicted_se(np.diag([4.0, 0.0, -1e-12, np.inf, np.nan]))
    assert se[0] == 2.0
    assert np.isinf(se[1:]).all()
