"""MATLAB ``.mat`` logs: v4/v5/v7 through scipy.io, v7.3 (HDF5) through h5py; a table.

Every numeric or logical vector is a signal by its variable name; a struct's fields are named
``struct.field`` (nested: ``a.b.c``); the columns of an N x k matrix are ``name[0]`` ...
``name[k-1]`` (a k x N matrix, one signal a row, is read the same: signals run along its
longer side). Scalars, text and cells are left out. The vectors as long as the time column
(``t``, ``time`` or the ``-c t=SOURCE`` mapping) form the log.

A file cut short (a variable's data running past the end of a v5 file; an HDF5 file shorter
than its superblock says) is refused in one line that says so.
"""

from __future__ import annotations

import os

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io.formats import Series, Signals, need

EXTENSIONS = (".mat",)
EXTRA = "mat"
#: a matrix with more columns than this is not a set of signals (an image, a lookup table)
MAX_COLUMNS = 64


def _add_array(name: str, a: np.ndarray, out: dict[str, Series]) -> None:
    """A numeric array as signals: a vector -> ``name``, an N x k (k x N) matrix -> ``name[j]``."""
    if a.dtype.kind not in "biuf" or a.size < 2:
        return
    a = np.asarray(a, dtype=float)
    if a.ndim == 2 and 1 in a.shape:
        a = a.ravel()
    elif a.ndim == 2 and a.shape[0] < a.shape[1]:  # k x N: one signal a row (MATLAB's habit)
        a = a.T
    if a.ndim == 1:
        out[name] = Series(a)
    elif a.ndim == 2 and a.shape[1] <= MAX_COLUMNS:
        for j in range(a.shape[1]):
            out[f"{name}[{j}]"] = Series(np.ascontiguousarray(a[:, j]))


def _walk_v5(name: str, obj, out: dict[str, Series]) -> None:
    if isinstance(obj, dict):
        for k, v in obj.items():
            _walk_v5(f"{name}.{k}" if name else k, v, out)
    elif isinstance(obj, np.ndarray):
        _add_array(name, obj, out)


def _load_v5(path: str) -> dict[str, Series]:
    sio = need("scipy.io", EXTRA, path, ".mat")
    try:
        data = sio.loadmat(path, simplify_cells=True)
    except Exception as exc:  # noqa: BLE001 - scipy's MatReadError and others on a foreign file
        if isinstance(exc, OSError) and "could not read bytes" in str(exc):
            raise LogError(f"the MATLAB file is cut short (a variable's data runs past its end, "
                           f"{os.path.getsize(path)} bytes): it was not closed properly or not "
                           "copied whole", path) from None
        raise LogError(f"is not a readable MATLAB file ({type(exc).__name__}: "
                       f"{str(exc)[:80]})", path) from None
    out: dict[str, Series] = {}
    for k, v in data.items():
        if not k.startswith("__"):
            _walk_v5(k, v, out)
    return out


def _walk_h5(name: str, node, h5py, out: dict[str, Series]) -> None:
    if isinstance(node, h5py.Group):
        for k in node:
            if not k.startswith("#"):
                _walk_h5(f"{name}.{k}" if name else k, node[k], h5py, out)
        return
    cls = node.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    if cls in ("char", "cell", "function_handle") or node.attrs.get("MATLAB_empty", 0):
        return
    if node.dtype.kind in "biuf":
        _add_array(name, np.asarray(node[()]).T, out)  # MATLAB is column-major


def _load_v73(path: str) -> dict[str, Series]:
    h5py = need("h5py", EXTRA, path, ".mat (v7.3)")
    out: dict[str, Series] = {}
    try:
        with h5py.File(path, "r") as fh:
            _walk_h5("", fh, h5py, out)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        if "truncated file" in str(exc):
            raise LogError(f"the MATLAB v7.3 (HDF5) file is cut short ({os.path.getsize(path)} "
                           "bytes, fewer than its header gives): it was not closed properly or "
                           "not copied whole", path) from None
        raise LogError(f"is not a readable MATLAB v7.3 file ({str(exc)[:100]})", path) from None
    return out


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole)."""
    with open(path, "rb") as fh:
        head = fh.read(128)
    hdf5 = head[:8] == b"\x89HDF\r\n\x1a\n" or (len(head) >= 128 and head[126:128] in (b"IM", b"MI")
                                                and head[124:126] == b"\x00\x02")
    return Signals(_load_v73(path) if hdf5 else _load_v5(path), table=True)
