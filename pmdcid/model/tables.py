"""Parameter tables shared by :class:`~pmdcid.model.Model` and the fit results: the same rows
(name, value, standard error, unit; an interval and a caveat where the logs only bound a
parameter) as text, HTML (notebooks), a dict and a pandas DataFrame. A bound is never shown as a
standard error: it is said in words, "between 0 and 0.25 N m (not identifiable ...)"."""

from __future__ import annotations

import html
import math
from typing import NamedTuple


class Row(NamedTuple):
    """One row: parameter name, value, standard error (NaN if unknown), unit, and where the
    logs only bound it, the interval (low, high) and the words that go with it."""

    name: str
    value: float
    stderr: float
    unit: str
    interval: tuple[float, float] | None = None
    caveat: str = ""


COLUMNS = ("parameter", "value", "stderr", "unit", "low", "high", "caveat")


def in_words(interval, unit: str, caveat: str = "") -> str:
    """``between LOW and HIGH UNIT (CAVEAT)``: a bounded parameter said as what it is."""
    why = f" ({caveat})" if caveat else ""
    unit = "" if unit == "1" else unit  # a share, a ratio: no unit to print
    return f"between {interval[0]:.3g} and {interval[1]:.3g} {unit}".rstrip() + why


def text_table(rows) -> str:
    """``parameter  value  ± stderr  unit`` lines (``± ?`` when the error is unknown); a bounded
    parameter as ``parameter  between LOW and HIGH UNIT (why)``."""
    rows = [Row(*r) for r in rows]
    w = max([len(r.name) for r in rows] + [9])
    lines = [f"{'parameter':<{w}} {'value':>13}   {'± stderr':<11} unit"]
    for r in rows:
        if r.interval is not None:
            lines.append(f"{r.name:<{w}} {in_words(r.interval, r.unit, r.caveat)}")
            continue
        s = f"± {r.stderr:.2g}" if math.isfinite(r.stderr) else "± ?"
        tail = f"  ({r.caveat})" if r.caveat else ""
        lines.append(f"{r.name:<{w}} {r.value:13.6g}   {s:<11} {r.unit}".rstrip() + tail)
    return "\n".join(lines)


def _html_row(r: Row) -> str:
    if r.interval is not None:
        return (f"<tr><td>{html.escape(r.name)}</td><td colspan='3'>"
                f"{html.escape(in_words(r.interval, r.unit, r.caveat))}</td></tr>")
    se = f"{r.stderr:.2g}" + (f" ({r.caveat})" if r.caveat else "") if math.isfinite(
        r.stderr) else ""
    se = html.escape(se)
    return (f"<tr><td>{html.escape(r.name)}</td><td>{r.value:.6g}</td><td>{se}</td>"
            f"<td>{html.escape(r.unit)}</td></tr>")


def html_table(rows, caption: str = "", pre: str = "") -> str:
    """An HTML table of ``rows`` (and ``pre``, the text form of a result, folded below it)."""
    cells = "".join(_html_row(Row(*r)) for r in rows)
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    out = (f"<table>{cap}<tr><th>parameter</th><th>value</th><th>± stderr</th><th>unit</th>"
           f"</tr>{cells}</table>")
    if pre:
        out += f"<details><summary>details</summary><pre>{html.escape(pre)}</pre></details>"
    return out


def rows_dict(rows) -> dict:
    """name -> {value, stderr, unit} (and ``interval``, ``caveat`` where set); an unknown
    standard error is None (JSON-safe)."""
    out = {}
    for r in (Row(*r) for r in rows):
        d = {"value": float(r.value),
             "stderr": float(r.stderr) if math.isfinite(r.stderr) else None, "unit": r.unit}
        if r.interval is not None:
            d["interval"] = [float(r.interval[0]), float(r.interval[1])]
        if r.caveat:
            d["caveat"] = r.caveat
        out[r.name] = d
    return out


def rows_frame(rows):
    """A pandas DataFrame with columns parameter, value, stderr (NaN if unknown), unit, low and
    high (a bounded parameter's interval, else NaN) and caveat (its words, else empty)."""
    import pandas as pd

    data = []
    for r in (Row(*r) for r in rows):
        low, high = r.interval if r.interval is not None else (math.nan, math.nan)
        data.append([r.name, r.value, r.stderr, r.unit, low, high, r.caveat])
    return pd.DataFrame(data, columns=list(COLUMNS))
