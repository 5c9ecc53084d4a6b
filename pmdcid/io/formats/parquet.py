"""Apache Parquet logs (``.parquet``, ``.pq``) through pyarrow: a table, as a CSV file.

Every numeric or boolean column is a signal by its name; a struct column's fields are named
``column.field``; a timestamp column is in seconds (from 1970: ``t`` then starts where the file
starts, as a CSV's does), and is the time when the file has no ``t`` and no other column of
times; a field's ``unit`` metadata (if the writer stored one) is its unit.
A file that starts as Parquet but lacks the footer Parquet writes last was cut short: one line
says so.
"""

from __future__ import annotations

import numpy as np

from pmdcid.errors import LogError
from pmdcid.io.formats import Series, Signals, need

EXTENSIONS = (".parquet", ".pq")
EXTRA = "parquet"
MAGIC = b"PAR1"


def _cut_short(path: str) -> bool:
    """True when ``path`` starts as a Parquet file but does not end as one (no footer)."""
    with open(path, "rb") as fh:
        head = fh.read(4)
        size = fh.seek(0, 2)
        fh.seek(max(0, size - 4))
        return head == MAGIC and (size < 12 or fh.read(4) != MAGIC)


def _unit(fld) -> str | None:
    meta = fld.metadata or {}
    raw = meta.get(b"unit") or meta.get(b"units")
    return raw.decode("utf-8", "replace") if raw else None


def _column(arr, typ, pa) -> np.ndarray | None:
    """A column as float64 seconds/values, None when it is not numeric."""
    if pa.types.is_timestamp(typ) or pa.types.is_duration(typ):
        ns = arr.cast(pa.int64()).to_numpy(zero_copy_only=False)
        unit = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[typ.unit]
        return ns.astype(float) * unit
    if pa.types.is_integer(typ) or pa.types.is_floating(typ) or pa.types.is_boolean(typ) \
            or pa.types.is_decimal(typ):
        # safe=False: an int64 beyond 2**53 (a time stamp in ns) is rounded, as numpy rounds it
        return np.asarray(arr.cast(pa.float64(), safe=False).to_numpy(zero_copy_only=False),
                          dtype=float)
    return None


def _flatten(name: str, arr, fld, pa, out: dict[str, Series]) -> None:
    typ = arr.type
    if pa.types.is_struct(typ):
        flat = arr.combine_chunks() if hasattr(arr, "combine_chunks") else arr
        for j in range(typ.num_fields):
            sub = typ.field(j)
            _flatten(f"{name}.{sub.name}", flat.field(j), sub, pa, out)
        return
    x = _column(arr, typ, pa)
    if x is not None:
        timed = pa.types.is_timestamp(typ) or pa.types.is_duration(typ)
        out[name] = Series(x, None, _unit(fld) or ("s" if timed else None))


def load(path: str, wanted: list[str] | None = None) -> Signals:
    """The file's signals (``wanted``, the mapped names, unused: the file is read whole)."""
    pa = need("pyarrow", EXTRA, path, ".parquet")
    pq = need("pyarrow.parquet", EXTRA, path, ".parquet")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as exc:
        if _cut_short(path):
            raise LogError("the Parquet file is cut short (no footer at its end): it was not "
                           "closed properly or not copied whole", path) from None
        msg = str(exc).strip().splitlines()[0][:100] if str(exc).strip() else type(exc).__name__
        raise LogError(f"is not a readable Parquet file ({msg})", path) from None
    out: dict[str, Series] = {}
    for fld, col in zip(table.schema, table.columns, strict=True):
        _flatten(fld.name, col, fld, pa, out)
    meta = {}
    for k, v in (table.schema.metadata or {}).items():
        key = k.decode("utf-8", "replace")
        if key == "kind":  # the one metadata key the tool reads (as ``# kind:`` in CSV)
            meta[key] = v.decode("utf-8", "replace")
    return Signals(out, table=True, meta=meta)
