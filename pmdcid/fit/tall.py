"""Very tall least-squares problems compressed before scipy's solver sees them.

A fit on a 2-million-sample log has a residual of m = 2e6 rows (per signal) and a handful of
parameters n. scipy's trust-region reflective solver (``method="trf"``, exact sub-problem)
keeps several m x n matrices at once: the Jacobian, its scaled copy inside an augmented matrix,
the SVD's input copy, U and the SVD's workspace, and a squared copy for the column norms; 80 MB
each with five parameters, 665 MB traced at the peak of such a fit (docs/performance.md).

Every quantity the solver computes from the residual ``f`` and the Jacobian ``J`` is a function
of ``J'J``, ``J'f`` and ``|f|`` only (the gradient ``J'f``, the column norms of ``J``, the
singular values and right vectors of the scaled ``J``, ``U'f``, the predicted reduction and the
cost). Take the thin QR factorisation ``[f J] = Q [rho c'; 0 R22]`` (the residual first): then
the (n+1)-row problem ``f~ = [rho, 0, ..., 0]``, ``J~ = [c'; R22] = Q'J`` has the same
``J~'J~ = J'J``, ``J~'f~ = J'f`` and ``|f~| = |f|``, so the solver takes the same steps (to
rounding) on matrices of n+1 rows. The residual returned for a trial point is ``[|f|, 0, ...]``
(only its norm is used before the point is accepted); the Jacobian at an accepted point is
``[c'; B]`` with ``c = J'f / |f|`` and ``B'B = J'J - c c'`` (:func:`compressed_jacobian`, any
square root will do: ``B = R22`` up to an orthogonal factor), from two BLAS products over the
full matrix and no m x n copy. The fit's result, its full residual and its full Jacobian are
those of the uncompressed problem.

Used by :func:`pmdcid.fit.solver.solve` only for problems of at least :data:`TALL_ROWS`
rows, so every ordinary log takes the uncompressed path bit for bit; on tall problems the
answers agree with it to rounding (``tests/fit/test_tall.py``: about 1e-12 relative).
"""

from __future__ import annotations

import numpy as np

#: residuals with at least this many rows are compressed (a 17-minute log at 1 kHz, one signal)
TALL_ROWS = 1 << 20
#: rows per block where a tall matrix is reduced a block at a time
#: (:func:`.covariance.column_norms`)
BLOCK_ROWS = 1 << 15


def compressed_jacobian(f: np.ndarray, JT: np.ndarray) -> np.ndarray:
    """``J~`` (n+1, n) for the residual ``f`` (m) and ``JT``, the (n, m) transpose of J: first
    row ``c = J'f / |f|``, then a square root ``B`` of ``J'J - c c'`` (its eigen-decomposition,
    negative rounding clipped), so that ``J~'J~ = J'J`` and ``J~'(|f|, 0, ...) = J'f``.

    From the Gram matrix ``J'J`` (one BLAS product, ~20 ms on 2 M rows with five parameters)
    rather than a Householder QR of ``[f J]`` (~180 ms, blocked): the solver's quantities agree
    to ~1e-14 relative (``tests/fit/test_tall.py``) and the fit's answer to rounding; the eigen
    square root accepts the rank-deficient J (a zero column) that a Cholesky factor would not.
    """
    rho = float(np.sqrt(np.dot(f, f)))
    c = (JT @ f) / rho if rho > 0 else np.zeros(JT.shape[0])
    S = JT @ JT.T - np.outer(c, c)
    lam, V = np.linalg.eigh(0.5 * (S + S.T))
    return np.vstack([c, np.sqrt(np.clip(lam, 0.0, None))[:, None] * V.T])


class Compressed:
    """``least_squares``' residual and Jacobian callables for the compressed problem of a
    :class:`~pmdcid.fit.fdjac.ForwardJacobian` ``fd`` (whose ``fun`` and ``__call__`` give
    the full residual and Jacobian); :meth:`full` gives them back at the solution."""

    def __init__(self, fd):
        self.fd = fd
        self._at_jac: tuple[bytes, np.ndarray] | None = None  # (point, full residual)

    def fun(self, z: np.ndarray) -> np.ndarray:
        f = self.fd.fun(z)
        out = np.zeros(len(z) + 1)
        out[0] = np.sqrt(np.dot(f, f))
        return out

    def jac(self, z: np.ndarray) -> np.ndarray:
        z = np.asarray(z, float)
        J = self.fd(z)  # the full forward differences (re-evaluates f at z if not the last)
        f = self.fd._last[1]
        self._at_jac = (z.tobytes(), f)
        return compressed_jacobian(f, J.T)

    def full(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The full residual and Jacobian at ``z`` (the solution: the last point whose
        Jacobian was taken; recomputed if it is not). The Jacobian is ``fd``'s own buffer."""
        z = np.asarray(z, float)
        if self._at_jac is None or self._at_jac[0] != z.tobytes():
            self.jac(z)
        return self._at_jac[1], self.fd._JT.T


__all__ = ["BLOCK_ROWS", "TALL_ROWS", "Compressed", "compressed_jacobian"]
