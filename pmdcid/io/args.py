"""Argument types of the library's front door: a wrong type is a TypeError (a wrong value a
ValueError) naming the argument, raised before any work -- never an AttributeError from deep
inside. Used by :mod:`pmdcid.api` and the ``Log.from_*`` constructors."""

from __future__ import annotations

import math
import os

import numpy as np

from pmdcid.errors import ArgumentError


def _kind(x) -> str:
    return type(x).__name__


def path_arg(x, name: str) -> str:
    """A file or folder path (str or os.PathLike)."""
    if isinstance(x, (str, os.PathLike)):
        return os.fspath(x)
    raise TypeError(f"{name} must be a path (str or os.PathLike), not {_kind(x)}")


def array_arg(x, name: str) -> np.ndarray:
    """A 1-D array of numbers (a list, a tuple, a numpy array, a pandas Series)."""
    if x is None or isinstance(x, (str, bytes, dict)) or np.ndim(x) != 1:
        what = f"a {np.ndim(x)}-D array" if isinstance(x, np.ndarray) else _kind(x)
        raise TypeError(f"{name} must be a 1-D array of numbers (one per sample), not {what}")
    try:
        return np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must hold numbers (one per sample)") from None


def frame_arg(df, name: str = "df"):
    """A pandas DataFrame (anything with ``columns`` and rows)."""
    if not (hasattr(df, "columns") and hasattr(df, "set_axis") and hasattr(df, "__len__")):
        hint = ": pandas.DataFrame(d) makes one from a dict" if isinstance(df, dict) else ""
        raise TypeError(f"{name} must be a pandas DataFrame, not {_kind(df)}{hint}")
    return df


def names_arg(x, name: str) -> list[str] | None:
    """None, a name, names separated by commas (``"J,bv"``, as the command line takes them), or
    an iterable of names."""
    if x is None:
        return None
    if isinstance(x, str):
        return [n.strip() for n in x.split(",") if n.strip()]
    try:
        out = list(x)
    except TypeError:
        raise TypeError(f"{name} must be a name or a list of names, not {_kind(x)}") from None
    bad = next((v for v in out if not isinstance(v, str)), None)
    if bad is not None or isinstance(x, dict):
        raise TypeError(f"{name} must be a name or a list of names (str), not a list holding "
                        f"{_kind(bad)}")
    return out


def number_arg(x, name: str, positive: bool = False, nonneg: bool = False) -> float | None:
    """None or a finite number (> 0 when ``positive``, >= 0 when ``nonneg``)."""
    if x is None:
        return None
    if isinstance(x, bool) or not isinstance(x, (int, float, np.number)):
        raise TypeError(f"{name} must be a number, not {_kind(x)}")
    v = float(x)
    bound = " > 0" if positive else " >= 0" if nonneg else ""
    if not math.isfinite(v) or (positive and v <= 0) or (nonneg and v < 0):
        raise ArgumentError(f"{name} must be a finite number{bound}, got {x!r}")
    return v


__all__ = ["array_arg", "frame_arg", "names_arg", "number_arg", "path_arg"]
