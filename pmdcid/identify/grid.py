"""Many simulations in one compiled call: the global stage of the simulation-error fits.

:func:`batch_cost` runs the shared kernel (:func:`pmdcid.simulate.kernel._run_into`, unchanged)
for every parameter set of a batch inside one numba ``prange`` loop (threads share the sets) and
returns, per set, the weighted sum of squared errors against the measured speed and angle:
``sum(((omega_sim + omega0 - omega_meas)/sigma_omega)^2) + sum(((theta_sim - theta_meas)/
sigma_theta)^2)``. Nothing of size (sets x samples) is kept, so a grid of hundreds of sets on a
120 s, 1 kHz log needs no more memory than a few simulations: one state buffer per thread,
reused set after set (fresh arrays of a long log cost page faults every set).

How the input is read between samples is applied (a late input, ``latency``, or a ``ramp``
reading, :mod:`pmdcid.simulate.input_grid`, on the same fine grid as
:func:`pmdcid.simulate.simulate_values`): fit-nonlinear's checks after its local stage (the
secant errors, the share's valley, dz's interval) read this cost at the fit's point, and held
where the fit read a slow log at ramp 0.9 it was 3700 chi-square units above the fit's own and
lowest elsewhere (tests/system/test_diagnose.py's 10 Hz triangle). A sensor delay is read the
same way, as the input applied that much later: the same response but for the log's first
``delay`` seconds, which the full simulation reads at the measured initial state (within 0.1 %
of its chi-square on the paper's triangle with 2.5 ms). Ignored, the checks profiled a model
without the fit's delay (bench/lawlag.py, 1 kHz, L/R 4 ms, seed 2: twice the fit's
chi-square, and dz written as 2.7e-5 ± 8e-13 against a true 0.064). The speed offset is
applied as it is.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model.lumped import kernel_values, lag_substeps
from pmdcid.simulate import compiled, param_vector
from pmdcid.simulate.initial import settled_start
from pmdcid.simulate.input_grid import read_input
from pmdcid.simulate.kernel import _run_into, discretize
from pmdcid.simulate.layout import (
    KM,
    LINEAR,
    NSTATE,
    OMEGA_STATE,
    THETA_STATE,
    L,
    R,
    state_vector,
)
from pmdcid.simulate.lazyjit import njit, prange
from pmdcid.simulate.substeps import choose_substeps


@njit(parallel=True, cache=True)
def _batch_cost(u, P, Phis, Gams, nsub, torque_driven, w_meas, th_meas, sw, sth,
                omega0, x0, bufs):  # pragma: no cover - compiled
    m = P.shape[0]
    nb = bufs.shape[0]
    cost = np.empty(m)
    for j0 in range(0, m, nb):  # nb sets at a time, each into its own buffer (reused)
        for jj in prange(min(nb, m - j0)):
            j = j0 + jj
            out = _run_into(u, P[j], Phis[j], Gams[j], nsub, torque_driven, x0[j], bufs[jj])
            cost[j] = _set_cost(out, w_meas, th_meas, sw, sth, omega0)
    return cost


@njit(cache=True, inline="always")
def _set_cost(out, w_meas, th_meas, sw, sth, omega0):  # pragma: no cover - compiled
    """One set's weighted squared error (dimensionless): its simulated states ``out`` against
    the measured speed [rad/s] and angle [rad] with noise stds sw, sth (0: not used); the
    speed sensor's offset omega0 [rad/s] added; non-finite residuals skipped."""
    c = 0.0
    for k in range(out.shape[0]):
        if sw > 0.0:
            r = (out[k, OMEGA_STATE] + omega0 - w_meas[k]) / sw
            if math.isfinite(r):
                c += r * r
        if sth > 0.0:
            r = (out[k, THETA_STATE] - th_meas[k]) / sth
            if math.isfinite(r):
                c += r * r
    return c


def batch_cost(log, vals_list: list[dict[str, float]], sigma: dict[str, float],
               nsub: int | None = None, x0=None) -> np.ndarray:
    """Weighted squared simulation error of each parameter set on one log (one compiled call).

    ``vals_list``: parameter dicts as :func:`pmdcid.simulate.param_values` gives;
    ``sigma``: noise std per signal used (``omega`` [rad/s], ``theta`` [rad]); a signal absent
    from ``sigma`` is not used. ``x0``: the state (i, omega, theta) every set starts from
    (default rest), an unmeasured current (NaN) settled for each set's own values
    (:func:`pmdcid.simulate.initial.settled_start`). Returns one cost per set (dimensionless
    chi-square).
    """
    torque = log.drive == "tau"
    mapped = [kernel_values(v, torque) for v in vals_list]  # a lumped model's electrical lag
    if len({m[1] for m in mapped}) > 1:  # sets with and without it: one call each
        cost = np.empty(len(vals_list))
        for flag in (False, True):
            idx = [k for k, m in enumerate(mapped) if m[1] == flag]
            cost[idx] = batch_cost(log, [vals_list[k] for k in idx], sigma, nsub, x0)
        return cost
    readings = {_reading(v) for v in vals_list}
    if len(readings) > 1:  # sets read the input differently: one call each
        cost = np.empty(len(vals_list))
        for rd in readings:
            idx = [k for k, v in enumerate(vals_list) if _reading(v) == rd]
            cost[idx] = batch_cost(log, [vals_list[k] for k in idx], sigma, nsub, x0)
        return cost
    lag = torque and not mapped[0][1]  # a lumped model's lag: steps that resolve it
    torque = mapped[0][1]
    P = np.array([param_vector(v) for v, _ in mapped], dtype=float)
    if torque:
        P[:, [R, L, KM]] = np.where(np.isfinite(P[:, [R, L, KM]]), P[:, [R, L, KM]], 1.0)
    dt = log.dt
    if nsub is None:
        nsub = max(choose_substeps(dt, p) for p in P)
    if lag:
        nsub = max(nsub, max(lag_substeps(dt, v["L"]) for v, _ in mapped))
    latency, ramp = _reading(vals_list[0])
    u, dt, nsub, q = read_input(np.asarray(log.u, float), dt, nsub, latency, ramp,
                                log.input_within())
    h = dt / nsub
    Phi = np.empty((len(P), 4, 3, 3))
    Gam = np.empty((len(P), 4, 3, 3))
    cache: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
    for k, p in enumerate(P):
        key = tuple(p[list(LINEAR)])
        if key not in cache:
            cache[key] = discretize(p, h, torque)
        Phi[k], Gam[k] = cache[key]
    nan = np.full(log.n, np.nan)
    w = _on_grid(log["omega"] if "omega" in sigma else nan, q)
    th = _on_grid(log["theta"] if "theta" in sigma else nan, q)
    omega0 = float(vals_list[0].get("omega0", 0.0))
    ahead = compiled.load()  # the C build (one thread) when current, else numba's JIT
    fn = ahead.batch_cost if ahead is not None else _batch_cost
    bufs = np.empty((min(_threads(ahead), len(P)), len(u), NSTATE))  # one simulation per thread
    starts = np.array([state_vector(settled_start(x0, float(u[0]), p, torque)) for p in P])
    return fn(np.ascontiguousarray(u, float), P, Phi, Gam, int(nsub), bool(torque), w, th,
              float(sigma.get("omega", 0.0)), float(sigma.get("theta", 0.0)), omega0,
              starts, bufs)


def _reading(vals: dict[str, float]) -> tuple[float, float | None]:
    """How a set reads the input between samples: (latency [s], ramp or None for held)."""
    latency = float(vals.get("latency", 0.0)) + float(vals.get("delay", 0.0))
    ramp = vals.get("ramp")
    if latency > 0.0 or ramp is not None:
        return latency, (None if ramp is None else float(ramp))
    return 0.0, None


def _on_grid(meas, q: int) -> np.ndarray:
    """The measured signal at every q-th row of the fine grid, NaN between (skipped)."""
    meas = np.asarray(meas, float)
    if q == 1:
        return np.ascontiguousarray(meas)
    out = np.full(len(meas) * q, np.nan)
    out[::q] = meas
    return out


def _threads(ahead) -> int:
    """Sets simulated at once: numba's threads under the JIT, one by the compiled C kernel."""
    if ahead is not None:
        return 1
    import numba

    return max(1, int(numba.get_num_threads()))
