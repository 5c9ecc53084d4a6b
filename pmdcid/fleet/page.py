"""``fleet.html``: one self-contained page (figures embedded as base64 PNG) with the fleet's
parameter distributions, the outliers and why, the drift of units measured more than once, the
population priors, the limits and the units that failed. Every string from the user (unit
names, attributes, file names, error messages) is HTML-escaped."""

from __future__ import annotations

import base64
import html
import math

from pmdcid.fleet import drift as drift_rules
from pmdcid.fleet import population as pop_rules
from pmdcid.report.html import CSS, fmt


def esc(text) -> str:
    return html.escape(str(text), quote=True)


def _table(head: list[str], rows: list[list[str]]) -> str:
    """An HTML table; ``rows`` cells are already HTML (numbers by :func:`_num`, text escaped)."""
    th = "".join(f"<th>{esc(h)}</th>" for h in head)
    body = "".join("<tr>" + "".join(r) + "</tr>" for r in rows)
    return f"<table><tr>{th}</tr>{body}</table>"


def _num(v, digits: int = 4) -> str:
    return f'<td class="num">{esc(fmt(v, digits))}</td>'


def _txt(v) -> str:
    return f"<td>{esc(v)}</td>"


def _img(png: bytes | None, alt: str) -> str:
    if png is None:
        return ""
    return f'<img alt="{esc(alt)}" src="data:image/png;base64,{base64.b64encode(png).decode()}">'


def _stats(res) -> str:
    rows = [[_txt(st.name), _txt(st.unit), _num(st.n), _num(st.median), _num(st.sigma, 3),
             _num(100 * st.rel_sigma, 3), _num(st.stderr, 3), _num(st.tau, 3),
             _num(res.borrowing.get(st.name, 0))] for st in res.stats.values()]
    return _table(["parameter", "unit", "units", "median", "robust sigma", "sigma %",
                   "median stderr", "prior sd (tau)", "units borrowing"], rows)


def _correlations(res) -> str:
    names = [n for n, st in res.stats.items() if st.sigma > 0]
    if len(names) < 2:
        return "<p class='note'>too few parameters with a spread.</p>"
    c = pop_rules.correlations(res.rows, names)
    rows = []
    for a, name in enumerate(names):
        cells = [_txt(name)]
        for b in range(len(names)):
            v = c[a, b]
            shade = "" if not math.isfinite(v) or a == b or abs(v) < 0.5 else (
                ' style="background:#fde2e1"' if v > 0 else ' style="background:#e1ecfd"')
            cells.append(f'<td class="num"{shade}>{esc(fmt(v, 2))}</td>')
        rows.append(cells)
    return _table(["", *names], rows)


def _outliers(res) -> str:
    if not res.outliers:
        return "<p>No outlier.</p>"
    rows = [[_txt(o.unit), _txt(o.parameter), _num(o.value), _num(o.z, 3), _num(o.z_own, 3),
             _txt(o.reason)] for o in res.outliers]
    return _table(["unit", "parameter", "value", "robust sigmas", "own stderrs", "why"], rows)


def _drift(res) -> str:
    sig = [d for d in res.drifts if d.significant]
    units = len({d.unit for d in res.drifts})
    head = (f"<p>{units} units measured more than once; a drift is at least "
            f"{drift_rules.Z_DRIFT:g} stderr of its slope and "
            f"{100 * drift_rules.MIN_CHANGE:g} % over the span.</p>")
    if not sig:
        return head + "<p>No significant drift.</p>"
    rows = [[_txt(d.unit), _txt(d.parameter), _num(d.n), _num(d.first), _num(d.last),
             _num(100 * d.change, 3), _num(d.days, 3), _num(d.z, 3)] for d in sig]
    return head + _table(["unit", "parameter", "measurements", "first", "last", "change %",
                          "days", "slope / stderr"], rows)


def _errors(res) -> str:
    bad = [r for r in res.rows if r["status"] != "ok"]
    if not bad:
        return "<p>Every unit was identified.</p>"
    return _table(["unit", "time", "error"],
                  [[_txt(r["unit"]), _txt(r.get("time") or ""), _txt(r.get("error", ""))]
                   for r in bad])


def _limits(res) -> str:
    if res.limits is None:
        return "<p class='note'>No limits given (<code>--limits</code>).</p>"
    failed = [r for r in res.rows if not r["pass"]]
    rows = [[_txt(r["unit"]), _txt(r.get("time") or ""), _txt(", ".join(r["failed"]))]
            for r in failed]
    return (f"<p>{len(res.rows) - len(failed)} of {len(res.rows)} measurements pass.</p>"
            + (_table(["unit", "time", "failed"], rows) if rows else ""))


def render(res, dist_png: bytes | None, drift_png: bytes | None) -> str:
    """The page of a :class:`~pmdcid.fleet.run.FleetResult` (module doc)."""
    ok = sum(r["status"] == "ok" for r in res.rows)
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'><title>pmdcid fleet</title>"
        f"<style>{CSS}</style></head><body><h1>Fleet: {esc(res.manifest)}</h1>",
        f"<p>{len(res.rows)} measurements of {len({r['unit'] for r in res.rows})} units: "
        f"{ok} identified, {len(res.rows) - ok} failed.</p>",
        "<h2>Distributions</h2><p class='note'>Each unit's latest estimate with its stderr; "
        f"blue line: the median, band: {pop_rules.Z_POP:g} robust sigmas; red: outliers.</p>",
        _img(dist_png, "parameter distributions"), _stats(res),
        "<h3>Rank correlations (Spearman)</h3>", _correlations(res),
        f"<h2>Outliers</h2><p class='note'>At least {pop_rules.Z_POP:g} robust sigmas from the "
        f"median and {pop_rules.Z_OWN:g} of the unit's own stderrs.</p>", _outliers(res),
        "<h2>Drift</h2>", _drift(res), _img(drift_png, "drift over time"),
        "<h2>Limits</h2>", _limits(res), "<h2>Failed units</h2>", _errors(res),
        "</body></html>"]
    return "\n".join(parts)


__all__ = ["esc", "render"]
