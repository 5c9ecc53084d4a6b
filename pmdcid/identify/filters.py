"""Two small filters the step fits need, in numpy: why not ``scipy.signal``.

Importing ``scipy.signal`` costs about a second (it builds the docstrings of its array-API
wrappers and pulls in scipy.stats and scipy.interpolate), more than every step fit of a rig
together. The step fits need only a Savitzky-Golay smoothing and slope (Strejc's inflection
tangent) and a 5-point running median (isolated speed spikes), the latency searches one
correlation: :func:`savgol`, :func:`medfilt5` and :func:`correlate_valid` compute what
``scipy.signal.savgol_filter(..., mode="interp")``, ``scipy.signal.medfilt(y, 5)`` and
``scipy.signal.correlate(a, v, mode="valid")`` do, to rounding
(tests/identify/test_filters.py compares
them).
"""

from __future__ import annotations

import math

import numpy as np


def savgol(y: np.ndarray, window: int, polyorder: int = 2, deriv: int = 0,
           delta: float = 1.0) -> np.ndarray:
    """Savitzky-Golay filter of ``y`` (odd ``window`` <= len(y), ``polyorder`` < ``window``):
    the ``deriv``-th derivative [unit of y per unit of ``delta``^deriv] of the least-squares
    polynomial through each window, evaluated at its centre; the first and last window//2
    outputs from the polynomial through the first and last ``window`` samples (scipy's
    ``mode="interp"``)."""
    y = np.asarray(y, dtype=float)
    half = window // 2
    x = np.arange(-half, half + 1, dtype=float)
    A = np.vander(x, polyorder + 1, increasing=True)
    h = np.linalg.pinv(A)[deriv] * (math.factorial(deriv) / delta ** deriv)
    out = np.empty_like(y)
    out[half:len(y) - half] = np.correlate(y, h, mode="valid")
    xe = np.arange(window, dtype=float)
    for seg, idx, pos in ((y[:window], slice(0, half), xe[:half]),
                          (y[-window:], slice(len(y) - half, len(y)), xe[window - half:])):
        poly = np.polynomial.polynomial.Polynomial.fit(xe, seg, polyorder, domain=[xe[0],
                                                                                   xe[-1]],
                                                        window=[xe[0], xe[-1]])
        out[idx] = poly.deriv(deriv)(pos) / delta ** deriv if deriv else poly(pos)
    return out


def medfilt5(y: np.ndarray) -> np.ndarray:
    """Running median over 5 samples, the signal padded with two zeros at each end (what
    ``scipy.signal.medfilt(y, 5)`` gives)."""
    y = np.asarray(y, dtype=float)
    padded = np.concatenate((np.zeros(2), y, np.zeros(2)))
    return np.median(np.lib.stride_tricks.sliding_window_view(padded, 5), axis=1)


def correlate_valid(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """sum_j a[k + j] v[j] for k = 0 .. len(a) - len(v) (``len(a) >= len(v)``), by FFT."""
    a, v = np.asarray(a, dtype=float), np.asarray(v, dtype=float)
    n = len(a) + len(v) - 1
    nfft = 1 << max(n - 1, 1).bit_length()
    full = np.fft.irfft(np.fft.rfft(a, nfft) * np.fft.rfft(v[::-1], nfft), nfft)
    return full[len(v) - 1:len(a)]


__all__ = ["correlate_valid", "medfilt5", "savgol"]
