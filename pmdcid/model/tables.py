"""Parameter tables shared by :class:`~pmdcid.model.Model` and the fit results: the same rows
(name, value, standard error, unit) as text, HTML (notebooks), a dict and a pandas DataFrame."""

from __future__ import annotations

import html
import math

#: one row: parameter name, value, standard error (NaN if unknown), unit
Row = tuple[str, float, float, str]
COLUMNS = ("parameter", "value", "stderr", "unit")


def text_table(rows: list[Row]) -> str:
    """``parameter  value  ± stderr  unit`` lines (``± ?`` when the error is unknown)."""
    w = max([len(r[0]) for r in rows] + [9])
    lines = [f"{'parameter':<{w}} {'value':>13}   {'± stderr':<11} unit"]
    for name, value, se, unit in rows:
        s = f"± {se:.2g}" if math.isfinite(se) else "± ?"
        lines.append(f"{name:<{w}} {value:13.6g}   {s:<11} {unit}".rstrip())
    return "\n".join(lines)


def html_table(rows: list[Row], caption: str = "", pre: str = "") -> str:
    """An HTML table of ``rows`` (and ``pre``, the text form of a result, folded below it)."""
    cells = "".join(
        f"<tr><td>{html.escape(n)}</td><td>{v:.6g}</td>"
        f"<td>{f'{se:.2g}' if math.isfinite(se) else ''}</td><td>{html.escape(u)}</td></tr>"
        for n, v, se, u in rows)
    cap = f"<caption>{html.escape(caption)}</caption>" if caption else ""
    out = (f"<table>{cap}<tr><th>parameter</th><th>value</th><th>± stderr</th><th>unit</th>"
           f"</tr>{cells}</table>")
    if pre:
        out += f"<details><summary>details</summary><pre>{html.escape(pre)}</pre></details>"
    return out


def rows_dict(rows: list[Row]) -> dict:
    """name -> {value, stderr, unit}; an unknown standard error is None (JSON-safe)."""
    return {n: {"value": float(v), "stderr": float(se) if math.isfinite(se) else None,
                "unit": u} for n, v, se, u in rows}


def rows_frame(rows: list[Row]):
    """A pandas DataFrame with columns parameter, value, stderr (NaN if unknown), unit."""
    import pandas as pd

    return pd.DataFrame([list(r) for r in rows], columns=list(COLUMNS))
