"""The one least-squares solver every fit of pmdcid goes through.

fit-electrical's and fit-mechanical's curve fits (:mod:`pmdcid.identify.steps`), the
simulation-error fits (:mod:`.simfit`: fit-mechanical's joint fit, fit-nonlinear, inverse
dynamics' refinement) and every diagnose refit (:meth:`.problem.Problem.fit`) call
:func:`solve`: scipy's trust-region reflective least squares on a scaled vector
``z = x / scale`` (each parameter of order one, so bounds, steps and tolerances mean the same
for an inertia of 1e-6 kg m^2 and a resistance of 3 ohm), one BLAS thread, and a residual
that is not finite at the start turned into a :class:`~pmdcid.errors.FitError`.

What the engine refuses itself, before scipy does with a bare ValueError: a parameter whose
bounds leave no room (lower not below upper: :func:`check_bounds`, e.g. a range the logs' speed
scale sets that lies outside the parameter's physical bounds; :meth:`.parameters.Parameters.start`
names the parameter), as a :class:`~pmdcid.errors.FitError`. What the engine catches: nothing
but the non-finite start. The model's own refusals
(:class:`~pmdcid.errors.PmdcidError`: a work bound, a parameter out of range) pass through
scipy unchanged to the stage that knows what to say; any other exception raised inside the
residual or the Jacobian (a ValueError from names zipped against a shorter vector, an
IndexError) is a bug and propagates with its traceback. (Before, every ValueError, scipy's
and the residual's alike, became "... failed" and the callers skipped a stage silently.)
Covariances (the textbook one and the correlated-residual sandwich) are :mod:`.covariance`'s.

The residual convention is the caller's, but every caller in pmdcid uses ``(simulated -
measured) / sigma``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pmdcid.errors import FitError


def blas_single_thread():
    """Context limiting BLAS to one thread (threadpoolctl), for the fits' small linear algebra.

    The least-squares steps work on tall, thin Jacobians; a multi-threaded BLAS spin-waits on a
    busy 2-core machine and makes each fit 2-4x slower than one thread does.
    """
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api="blas")


@dataclass
class Solution:
    """A solved least-squares problem in the scaled variable ``z``: ``x = z * scale``.

    ``fun`` is the residual at the solution, ``jac`` its Jacobian in ``x`` (the solver's own,
    forward differences), ``nfev`` the residual evaluations.
    """

    z: np.ndarray
    scale: np.ndarray
    fun: np.ndarray
    jac: np.ndarray
    nfev: int
    success: bool
    message: str

    @property
    def x(self) -> np.ndarray:
        return self.z * self.scale


def scale_of(x0: np.ndarray, typical: np.ndarray | float = 1.0) -> np.ndarray:
    """Scale of each parameter: its starting magnitude, or ``typical`` where the start is 0."""
    x0 = np.asarray(x0, float)
    return np.where(np.abs(x0) > 0, np.abs(x0), typical)


def solve(fun_z, z0, lo_z, hi_z, *, scale, diff_step=None, max_nfev: int | None = None,
          x_scale="jac", what: str = "fit", fills: bool = False,
          rows: int | None = None, parallel: bool = False) -> Solution:
    """Minimise ``sum(fun_z(z)**2)`` over ``lo_z <= z <= hi_z`` from ``z0`` (scaled vector).

    ``diff_step``: relative finite-difference step (one, or one per parameter; scipy's default
    when None). The cost of a simulation with stick-slip and a dead zone is only piecewise
    smooth: the callers pass steps large enough to cross the kernel's event quantisation.
    ``what`` names the fit in the error raised when the residual is not finite at ``z0``
    (:func:`finite_at_start`; the only error the engine makes of the solver's). ``fills``:
    ``fun_z(z, out=row)`` writes the residual into ``row`` (saves a copy per evaluation). The
    Jacobian is scipy's forward differences, computed into one preallocated matrix
    (:mod:`.fdjac`): the same numbers as ``jac="2-point"``. ``rows``: the residual's length
    when known; a residual of :data:`.tall.TALL_ROWS` rows or more is compressed to n+1 rows
    before the solver sees it (:mod:`.tall`: the same steps to rounding, in bounded memory).
    ``parallel``: the Jacobian's columns run on threads (``fun_z`` must then be safe to call from
    several threads at once: no shared scratch buffers); the same numbers for any thread count.
    """
    from pmdcid.fit.fdjac import ForwardJacobian
    from pmdcid.fit.tall import TALL_ROWS, Compressed

    check_bounds(lo_z, hi_z, what)
    z0 = np.clip(np.asarray(z0, float), lo_z, hi_z)
    fd = ForwardJacobian(finite_at_start(fun_z, what), diff_step, lo_z, hi_z, fills=fills,
                         parallel=parallel)
    tall = (Compressed(fd) if rows is not None and rows >= TALL_ROWS and fd.jac is fd
            else None)
    fun, jac = (tall.fun, tall.jac) if tall else (fd.fun, fd.jac)
    with blas_single_thread():
        sol = _least_squares(fun, z0, (lo_z, hi_z), diff_step, max_nfev, x_scale, jac)
        if tall:  # the full residual and Jacobian at the solution (the Jacobian in place)
            sol.fun, sol.jac = tall.full(sol.x)
            sol.jac /= scale[None, :]
    jac = sol.jac if tall else sol.jac / scale[None, :]
    fd._JT = fd._last = None  # scipy's wrappers keep fd in reference cycles: free its arrays now
    return Solution(sol.x, np.asarray(scale, float), sol.fun, jac, int(sol.nfev),
                    bool(sol.success), str(sol.message))


def check_bounds(lo_z, hi_z, what: str) -> None:
    """Every parameter's lower bound strictly below its upper one, else a
    :class:`~pmdcid.errors.FitError` naming ``what`` (scipy would raise a bare ValueError)."""
    lo, hi = np.broadcast_arrays(np.asarray(lo_z, float), np.asarray(hi_z, float))
    bad = np.flatnonzero(~(lo < hi))
    if bad.size:
        k = int(bad[0])
        raise FitError(f"{what} failed: parameter {k + 1} has no room between its bounds "
                       f"[{lo[k]:.3g}, {hi[k]:.3g}] (scaled): check the units and scale of "
                       "the logs' columns")


def finite_at_start(fun_z, what: str):
    """``fun_z`` whose first evaluation (scipy's, at the starting point) must be finite, else a
    :class:`~pmdcid.errors.FitError` naming ``what``: scipy would refuse the problem with a
    bare ValueError, indistinguishable from a bug in the residual. Later points may be
    non-finite: the trust region rejects such a step and shrinks."""
    first = [True]

    def checked(z, *args, **kwargs):
        f = fun_z(z, *args, **kwargs)
        if first[0]:
            first[0] = False
            got = kwargs.get("out") if f is None else f
            if got is not None and not np.all(np.isfinite(got)):
                raise FitError(f"{what} failed: the residual is not finite at the starting "
                               "values (the simulation diverged or a signal is not finite)")
        return f

    return checked


def _least_squares(fun, z0, bounds, diff_step, max_nfev, x_scale, jac="2-point"):
    from scipy.optimize import least_squares

    return least_squares(fun, z0, jac=jac, bounds=bounds, method="trf", diff_step=diff_step,
                         max_nfev=max_nfev, x_scale=x_scale)


__all__ = ["Solution", "blas_single_thread", "check_bounds", "finite_at_start", "scale_of",
           "solve"]
