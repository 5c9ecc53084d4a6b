"""scipy's forward-difference Jacobian for ``least_squares``, in one preallocated matrix.

``least_squares(jac="2-point")`` builds each Jacobian of an m-row residual from n lists of
m-vectors (the evaluations, their differences, the quotients) and then the matrix: about three
m x n copies at once. For a 2-million-row log that is several hundred megabytes, and every copy
above glibc's 32 MB mmap threshold is fresh memory to page-fault in, the superlinear part of a
long fit. :class:`ForwardJacobian` gives ``least_squares`` a ``jac`` callable that computes the
same numbers (scipy's own step rule and bound handling, the same differences and quotients in
the same memory layout) with each evaluation written straight into its row of one matrix,
allocated once per solve. The fits' results are bit for bit those of ``jac="2-point"``
(``tests/fit/test_fdjac.py``); when scipy's step helpers are not importable (a later scipy
renamed them), :meth:`ForwardJacobian.jac` is ``"2-point"`` itself.

The columns are independent simulations: with ``parallel``, they are shared with the spare
CPUs (:func:`pmdcid.runtime.cpus.pmap`; ``PMDCID_THREADS=1`` turns it off). Each column is
written into its own row by the same code as serially: the Jacobian is bit for bit the same
for any number of threads.
"""

from __future__ import annotations

import numpy as np

from pmdcid.runtime.cpus import pmap

try:  # scipy's own step rule: the steps must be exactly those of jac="2-point"
    from scipy.optimize._numdiff import _adjust_scheme_to_bounds, _compute_absolute_step
except ImportError:  # pragma: no cover - a scipy without these helpers: its "2-point" serves
    _compute_absolute_step = _adjust_scheme_to_bounds = None


class ForwardJacobian:
    """The residual (:meth:`fun`, remembering its last value) and its forward-difference Jacobian
    (:meth:`jac`) for one ``least_squares`` call with relative steps ``rel_step`` (scipy's
    default when None) inside bounds ``lb``, ``ub`` of the solver's vector. With ``fills``,
    ``resid(x, out=row)`` writes the residual into ``row`` (an m-vector)."""

    def __init__(self, resid, rel_step, lb, ub, fills: bool = False, parallel: bool = False):
        self.resid = resid
        self.fills = fills
        self.parallel = parallel
        self.rel_step = rel_step
        self.lb = np.asarray(lb, float)
        self.ub = np.asarray(ub, float)
        self._last: tuple[bytes, np.ndarray] | None = None
        self._JT: np.ndarray | None = None

    @property
    def jac(self):
        """What to pass as ``least_squares(jac=...)``."""
        return self if _compute_absolute_step is not None else "2-point"

    def fun(self, x: np.ndarray) -> np.ndarray:
        f = np.atleast_1d(self.resid(x))
        self._last = (np.asarray(x, float).tobytes(), f)
        return f

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x0 = np.asarray(x, float)
        f0 = self._last[1] if self._last and self._last[0] == x0.tobytes() else self.fun(x0)
        h = _compute_absolute_step(self.rel_step, x0, f0, "2-point")
        h, _ = _adjust_scheme_to_bounds(x0, h, 1, "1-sided", self.lb, self.ub)
        n, m = x0.size, f0.size
        if self._JT is None or self._JT.shape != (n, m):
            self._JT = np.empty((n, m))
        JT = self._JT  # scipy fills the transpose and returns its .T: the same layout here

        def column(i):
            x1 = np.copy(x0)
            x1[i] = x0[i] + h[i]
            row = JT[i]
            if self.fills:
                self.resid(x1, out=row)
                np.subtract(row, f0, out=row)
            else:
                np.subtract(np.atleast_1d(self.resid(x1)), f0, out=row)
            np.divide(row, (x0[i] + h[i]) - x0[i], out=row)

        pmap(column, range(n), self.parallel)
        return JT.T



__all__ = ["ForwardJacobian"]
