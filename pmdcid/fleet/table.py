"""The fleet's tables: ``units.parquet`` (pyarrow) and ``outliers.csv``.

``units.parquet`` has one row per measurement (unit, time), in the manifest's order, with the
columns: ``unit``, ``time`` (UTC timestamp, null when the manifest gives none), ``status``
(``ok``/``error``), ``error`` (one line), the manifest's attributes (text), ``effects`` (the
effects added, comma-separated), ``lumped`` (per-volt parameters), every parameter ``p`` with
``p_stderr`` [the parameter's unit] (null where the unit's logs only bound it: then ``p_low``
and ``p_high``, the interval, columns present when some unit has one), the population priors
``p_pooled`` and ``p_pooled_stderr`` with ``borrowed`` (the parameters where the prior's
weight is 10 % or more, comma-separated), ``outlier`` (the parameters on which the unit is an
outlier), ``drifting`` (the parameters drifting significantly), ``pass`` and ``failed`` (with
``--limits``),
``warnings``, ``logs`` (the log files, ``;``-separated), ``seconds`` and ``cpu_seconds`` (the
task's wall and CPU time) and ``key`` (the journal key).
"""

from __future__ import annotations

import csv
import io
import math
from datetime import datetime

#: extra the parquet writer needs
EXTRA = "pip install 'pmdcid[fleet]'"


#: the columns of every table besides attributes and parameters
FIXED = ("unit", "time", "status", "error", "effects", "lumped", "borrowed", "outlier",
         "drifting", "pass", "failed", "warnings", "logs", "seconds", "cpu_seconds", "key")


def _pyarrow():
    from pmdcid.errors import PmdcidError

    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise PmdcidError(f"writing units.parquet needs pyarrow: {EXTRA}") from None
    return pa, pq


def _num(v) -> float | None:
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _time(text):
    return datetime.fromisoformat(text) if text else None


def columns(rows: list[dict], names: list[str], pooled: list[str], attrs: list[str],
            limits: bool) -> dict[str, list]:
    """The table's columns (module doc) as lists, from the analysed rows."""
    cols: dict[str, list] = {
        "unit": [r["unit"] for r in rows],
        "time": [_time(r.get("time")) for r in rows],
        "status": [r["status"] for r in rows],
        "error": [r.get("error", "") for r in rows],
    }
    taken = set(FIXED) | set(names) | {f"{n}{x}" for n in names
                                       for x in ("_stderr", "_low", "_high")} | {
        f"{n}_pooled{x}" for n in pooled for x in ("", "_stderr")}
    for a in attrs:  # an attribute named like a column of ours keeps its value as attr_NAME
        cols[a if a not in taken else f"attr_{a}"] = [r.get("attrs", {}).get(a) for r in rows]
    cols["effects"] = [",".join(r.get("effects", [])) for r in rows]
    cols["lumped"] = [bool(r.get("lumped", False)) for r in rows]
    for n in names:
        got = [r.get("params", {}).get(n) for r in rows]
        cols[n] = [_num(g[0]) if g else None for g in got]
        cols[f"{n}_stderr"] = [_num(g[1]) if g else None for g in got]
        if any(g and len(g) > 3 for g in got):  # some unit's logs only bound it
            cols[f"{n}_low"] = [_num(g[3]) if g and len(g) > 3 else None for g in got]
            cols[f"{n}_high"] = [_num(g[4]) if g and len(g) > 3 else None for g in got]
    for n in pooled:
        got = [r.get("pooled", {}).get(n) for r in rows]
        cols[f"{n}_pooled"] = [_num(g[0]) if g else None for g in got]
        cols[f"{n}_pooled_stderr"] = [_num(g[1]) if g else None for g in got]
    for c in ("borrowed", "outlier", "drifting"):
        cols[c] = [",".join(r.get(c, [])) for r in rows]
    if limits:
        cols["pass"] = [bool(r["pass"]) for r in rows]
        cols["failed"] = [",".join(r["failed"]) for r in rows]
    cols["warnings"] = [" | ".join(r.get("warnings", [])) for r in rows]
    cols["logs"] = [";".join(r.get("logs", [])) for r in rows]
    cols["seconds"] = [_num(r.get("seconds")) for r in rows]
    cols["cpu_seconds"] = [_num(r.get("cpu_seconds")) for r in rows]
    cols["key"] = [r["key"] for r in rows]
    return cols


def parquet_bytes(cols: dict[str, list]) -> bytes:
    """``cols`` as a parquet file's bytes (types: text, UTC timestamps, float64, bool)."""
    pa, pq = _pyarrow()
    types = {"time": pa.timestamp("us", tz="UTC"), "lumped": pa.bool_(), "pass": pa.bool_(),
             "seconds": pa.float64(), "cpu_seconds": pa.float64()}
    arrays, fields = [], []
    for name, vals in cols.items():
        typ = types.get(name)
        if typ is None:
            numeric = name not in FIXED and all(v is None or isinstance(v, float) for v in vals)
            typ = pa.float64() if numeric else pa.string()
        arrays.append(pa.array(vals, type=typ))
        fields.append(pa.field(name, typ))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields))
    sink = pa.BufferOutputStream()
    pq.write_table(table, sink)
    return sink.getvalue().to_pybytes()


def is_units_parquet(path: str) -> bool:
    """Whether ``path`` is a units.parquet a fleet wrote (a parquet table with the fleet's
    ``unit``, ``status`` and ``error`` columns)."""
    _, pq = _pyarrow()
    try:
        return {"unit", "status", "error"} <= set(pq.read_schema(path).names)
    except (OSError, ValueError):  # pyarrow's ArrowInvalid is a ValueError
        return False


def outliers_csv(outliers) -> str:
    """``unit,parameter,value,reason`` (one row per outlier pair; values as repr floats)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["unit", "parameter", "value", "reason"])
    for o in outliers:
        w.writerow([o.unit, o.parameter, repr(float(o.value)), o.reason])
    return buf.getvalue()


__all__ = ["columns", "outliers_csv", "parquet_bytes"]
