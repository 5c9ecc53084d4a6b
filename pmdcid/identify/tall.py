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
``Q'J``, from a QR of ``[f J]`` accumulated over blocks of rows (no m x n copy). The fit's
result, its full residual and its full Jacobian are those of the uncompressed problem.

Used by :func:`pmdcid.identify.solver.solve` only for problems of at least :data:`TALL_ROWS`
rows, so every ordinary log takes the uncompressed path bit for bit; on tall problems the
answers agree with it to rounding (``tests/test_tall.py``: about 1e-12 relative).
"""

from __future__ import annotations

import numpy as np

#: residuals with at least this many rows are compressed (a 17-minute log at 1 kHz, one signal)
TALL_ROWS = 1 << 20
#: rows per block of the accumulated QR factorisation (1.5 MB blocks for five parameters)
BLOCK_ROWS = 1 << 15


def r_factor(f: np.ndarray, JT: np.ndarray, block: int = BLOCK_ROWS) -> np.ndarray:
    """Upper-triangular R, (n+1, n+1), of the thin QR of the m x (n+1) matrix ``[f J]``, with
    ``JT`` the (n, m) transpose of J, accumulated over blocks of ``block`` rows; the first row
    has ``R[0, 0] >= 0`` (so ``R[0, 0] = |f|``). ``R'R = [f J]'[f J]``."""
    n1 = JT.shape[0] + 1
    R = np.zeros((0, n1))
    for a in range(0, len(f), block):
        b = min(a + block, len(f))
        A = np.empty((R.shape[0] + b - a, n1))
        A[:R.shape[0]] = R
        A[R.shape[0]:, 0] = f[a:b]
        A[R.shape[0]:, 1:] = JT[:, a:b].T
        R = np.linalg.qr(A, mode="r")
    if R.shape[0] < n1:  # fewer rows than columns: pad with zero rows (same R'R)
        R = np.vstack([R, np.zeros((n1 - R.shape[0], n1))])
    if R[0, 0] < 0:
        R[0] = -R[0]
    return R


class Compressed:
    """``least_squares``' residual and Jacobian callables for the compressed problem of a
    :class:`~pmdcid.identify.fdjac.ForwardJacobian` ``fd`` (whose ``fun`` and ``__call__`` give
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
        return r_factor(f, J.T)[:, 1:]

    def full(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The full residual and Jacobian at ``z`` (the solution: the last point whose
        Jacobian was taken; recomputed if it is not). The Jacobian is ``fd``'s own buffer."""
        z = np.asarray(z, float)
        if self._at_jac is None or self._at_jac[0] != z.tobytes():
            self.jac(z)
        return self._at_jac[1], self.fd._JT.T


__all__ = ["BLOCK_ROWS", "TALL_ROWS", "Compressed", "r_factor"]
