"""report/metrics.py: a signal whose measurement never changes (JSON has no inf)."""

from __future__ import annotations

import json

import numpy as np

from pmdcid.report.metrics import signal_metrics


def test_constant_measurement_gives_null_and_says_why(rng):
    """A speed logged as exact zeros: NRMSE and fit are null in metrics.json (strict JSON), the
    reason in words beside them, the RMS error still in the signal's unit."""
    n = 2000
    u = np.where(np.arange(n) > 500, 1.5, 0.0)
    sim = rng.normal(0.0, 0.2, n)
    m = signal_metrics(sim, np.zeros(n), u, np.zeros(n, bool))
    json.dumps(m, allow_nan=False)  # raises on inf or nan
    assert m["nrmse"] is None and m["fit_percent"] is None
    assert "never changes" in m["nrmse_undefined"]
    assert m["rms"] == np.sqrt(np.mean(sim**2))
    moving = signal_metrics(sim, sim + rng.normal(0.0, 0.02, n), u, None)
    assert "nrmse_undefined" not in moving and 0.05 < moving["nrmse"] < 0.2
