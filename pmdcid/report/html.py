"""The report page: one self-contained HTML file, figures embedded as base64 PNG.

Every number on the page comes from ``metrics.json``: each numeric cell carries the path of its
value there (``data-m="logs.0.signals.omega.nrmse"``) so that a check can compare the two.
"""

from __future__ import annotations

import base64
import html
import math

CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;margin:0 auto;
max-width:1150px;padding:1em 1.5em;color:#222;line-height:1.4}
h1{font-size:1.5em;margin-bottom:.2em}h2{border-bottom:1px solid #ccc;padding-bottom:.2em;
margin-top:1.6em}h3{margin-bottom:.3em}
table{border-collapse:collapse;margin:.5em 0;font-size:.88em;max-width:100%}
th,td{border:1px solid #ddd;padding:.25em .45em;text-align:left;vertical-align:top}
th{background:#f3f3f3}td.num{text-align:right;font-variant-numeric:tabular-nums}
td.why{font-size:.85em;color:#444;max-width:34em}
.scroll{max-width:100%;overflow-x:auto}
img{max-width:100%;height:auto;display:block;margin:.5em 0;border:1px solid #eee}
.note{color:#555;font-size:.9em}.good{color:#1a7f37}.bad{color:#b42318}
code{background:#f6f6f6;padding:0 .2em;overflow-wrap:anywhere}
ul.notes{padding-left:1.2em}ul.notes li{margin:.2em 0}
.sev-warning{color:#8a3c00;font-weight:600}.sev-note{color:#1f4e9c;font-weight:600}
.legend-meas{display:inline-block;width:2.2em;height:.45em;background:#9e9e9e;
vertical-align:middle}.legend-sim{display:inline-block;width:2.2em;height:2px;
background:#c4001a;vertical-align:middle}
"""


def fmt(v, digits: int = 4) -> str:
    """A number as shown on the page (``digits`` significant figures; '-' when missing)."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    return f"{v:.{digits}g}"


def get_path(metrics: dict, path: str):
    """The value at a dotted path of ``metrics`` (list indices as numbers). A key may hold dots
    itself (a parameter ``my.param``, a log ``run.2``): the longest key present is taken."""
    cur, parts = metrics, path.split(".")
    while parts:
        if isinstance(cur, list):
            cur, parts = cur[int(parts[0])], parts[1:]
            continue
        n = next((k for k in range(len(parts), 0, -1) if ".".join(parts[:k]) in cur), 1)
        cur, parts = cur[".".join(parts[:n])], parts[n:]
    return cur


class Page:
    """Accumulates HTML; :meth:`num` renders a cell from a path into the metrics."""

    def __init__(self, metrics: dict):
        self.m = metrics
        self.parts: list[str] = []

    def add(self, text: str) -> None:
        self.parts.append(text)

    def num(self, path: str, digits: int = 4, after: str = "") -> str:
        """A numeric cell; ``after``: HTML below the number in the same cell."""
        return (f'<td class="num" data-m="{html.escape(path)}">'
                f"{fmt(get_path(self.m, path), digits)}{after}</td>")

    def span(self, path: str, digits: int = 4) -> str:
        return (f'<span data-m="{html.escape(path)}">'
                f"{fmt(get_path(self.m, path), digits)}</span>")

    def img(self, name: str, png: bytes, alt: str) -> None:
        b64 = base64.b64encode(png).decode("ascii")
        self.add(f'<img src="data:image/png;base64,{b64}" alt="{html.escape(alt)}" '
                 f'data-file="{html.escape(name)}">')

    def text(self) -> str:
        return "\n".join(self.parts)


def _esc(x) -> str:
    return html.escape(str(x))


def _params(p: Page) -> None:
    m = p.m
    p.add('<section id="parameters"><h2>Model parameters</h2>')
    p.add(f"<p>Model file <code>{_esc(m['model_path'])}</code>; effects beyond the paper's "
          f"model: <b>{_esc(', '.join(m['effects']) or 'none')}</b>.</p>")
    if m.get("lumped"):
        p.add("<p><span class='sev-note'>note:</span> lumped model: per-volt parameters "
              "(voltage and speed only, no current, no datasheet); torques are in volts.</p>")
    p.add("<div class='scroll'><table><tr><th>parameter</th><th>value</th><th>std. error</th>"
          "<th>rel. error [%]</th><th>unit</th><th>stage</th><th>why / caveat</th></tr>")
    for name, par in m["parameters"].items():
        base = f"parameters.{name}"
        p.add(f"<tr id='param-{_esc(name)}'><td>{_esc(name)}</td>{_value_cells(p, base, par)}"
              f"<td>{_esc(par['unit'])}</td><td>{_esc(par['stage'])}</td>"
              f"<td class='why'>{_caveat(par)}"
              f"{_why(m, lambda n, name=name: name in n['rows'])}</td></tr>")
    p.add("</table></div></section>")


def _value_cells(p: Page, base: str, par: dict) -> str:
    """Value, standard error, relative error; a parameter the logs only bound in words over
    the three cells ("between 0 and 0.25 N m"), never as a standard error."""
    if par.get("interval") is not None:
        return (f"<td colspan='3'>between {p.span(base + '.interval.0', 3)} and "
                f"{p.span(base + '.interval.1', 3)} {_esc(par['unit'])} (only bounded: no "
                "standard error)</td>")
    return (f"{p.num(base + '.value', 6)}{p.num(base + '.stderr', 3)}"
            f"{p.num(base + '.rel_stderr_percent', 3)}")


def _caveat(par: dict) -> str:
    """A parameter's own words (why it is only bounded, what to record; a standard error that
    is a lower bound), above the notes that qualify it."""
    c = par.get("caveat")
    return f"<span class='sev-note'>note:</span> {_esc(c)}<br>" if c else ""


def _note_item(n: dict) -> str:
    sev = "warning" if n["severity"] == "warning" else "note"
    return f"<span class='sev-{sev}'>{sev}:</span> {_esc(n['text'])}"


def _why(m: dict, wanted) -> str:
    """The notes ``wanted(note)`` selects, one per line."""
    return "<br>".join(_note_item(n) for n in m.get("notes", []) if wanted(n))


def _notes(p: Page) -> None:
    """Every warning and note, at the top: what qualifies the numbers below."""
    notes = p.m.get("notes") or []
    p.add("<section id='notes'><h2>Warnings and notes</h2>")
    if not notes:
        p.add("<p>None: no stage qualified its numbers.</p></section>")
        return
    p.add("<p class='note'>What the stages said about the numbers below; each is repeated "
          "beside the parameter or log it concerns.</p><ul class='notes'>")
    for n in notes:
        where = ", ".join(n["rows"]) or (p.m["logs"][n["log_index"]]["name"]
                                         if n["log_index"] is not None else "")
        p.add(f"<li>{_note_item(n)}{f' <i>({_esc(where)})</i>' if where else ''}</li>")
    p.add("</ul></section>")


def _nrmse_cells(p: Page, b: str, sm: dict) -> str:
    """The NRMSE and fit cells of one signal, in words where undefined (a constant
    measurement)."""
    if sm.get("nrmse_undefined"):
        return f'<td colspan="2">{_esc(sm["nrmse_undefined"])}</td>'
    return f"{p.num(b + '.nrmse')}{p.num(b + '.fit_percent')}"


def _errors(p: Page, figs: dict[str, bytes]) -> None:
    m = p.m
    p.add('<section id="errors"><h2>Errors per log and signal</h2>')
    p.add(f"<p class='note'>NRMSE = RMS(sim − meas) / std(meas); fit = 100 (1 − NRMSE) as "
          f"MATLAB <code>compare</code>. Near zero speed: |ω<sub>meas</sub>| below "
          f"{p.span('low_speed_percent')} % of the log's largest |ω<sub>meas</sub>| "
          f"(regime NRMSE = regime RMS error / std of the whole measurement). "
          f"Resid: number of the {p.span('max_lag')} auto- (and {p.span('cross_lags')} cross-) "
          f"correlation lags outside the 99 % band.</p>")
    p.add("<div class='scroll'><table><tr><th>log</th><th>signal [unit]</th><th>NRMSE</th>"
          "<th>fit [%]</th><th>RMS error</th><th>max |error|</th>"
          "<th>near-zero NRMSE</th><th>rest NRMSE</th><th>near-zero max |error|</th>"
          "<th>auto lags out</th><th>cross lags out</th></tr>")
    for k, lg in enumerate(m["logs"]):
        for s, sm in lg["signals"].items():
            b = f"logs.{k}.signals.{s}"
            reg = "".join(p.num(f"{b}.{r}.{q}") if r in sm else "<td>–</td>"
                          for r, q in (("low_speed", "nrmse"), ("high_speed", "nrmse"),
                                       ("low_speed", "max_abs")))
            derived = " (derived)" if sm["derived"] else ""
            lu = lg.get("logged_units", {}).get(s)
            own = (f"<br><small>= {p.span(b + '.rms_logged')} {_esc(lu['source'])}</small>"
                   if lu and "rms_logged" in sm else "")  # and in the log's own unit
            rms = p.num(b + ".rms", after=own)
            p.add(f"<tr><td>{_esc(lg['name'])}</td><td>{_esc(s)}{derived}<br><small>"
                  f"[{_esc(sm['unit'])}]</small></td>"
                  f"{_nrmse_cells(p, b, sm)}{rms}"
                  f"{p.num(b + '.max_abs')}{reg}"
                  f"{p.num(b + '.resid.auto.outside')}{p.num(b + '.resid.cross.outside')}</tr>")
    p.add("</table></div>")
    p.img("fit.png", figs["fit.png"], "fit per log and signal")
    p.add("</section>")


def _before_after(p: Page, figs: dict[str, bytes]) -> None:
    ba = p.m["before_after"]
    p.add('<section id="before-after"><h2>Error before and after the added effects</h2>')
    p.add(f"<p>Before: the model without <b>{_esc(', '.join(ba['effects']) or 'its effects')}"
          f"</b> ({_esc(ba['before_label'])}); after: the model as given.</p>")
    p.add("<table><tr><th>log</th><th>signal</th><th>NRMSE before</th><th>NRMSE after</th>"
          "<th>change [%]</th></tr>")
    for k, name in enumerate(ba["logs"]):
        for s in ba["after"][k]:
            b = f"before_after.before.{k}.{s}"
            a = f"before_after.after.{k}.{s}"
            c = f"before_after.change_percent.{k}.{s}"
            p.add(f"<tr><td>{_esc(name)}</td><td>{_esc(s)}</td>{p.num(b)}{p.num(a)}"
                  f"{p.num(c, 3)}</tr>")
    for s in ba["mean_after"]:
        p.add(f"<tr><th>mean</th><th>{_esc(s.replace('_nrmse', ''))}</th>"
              f"{p.num('before_after.mean_before.' + s)}{p.num('before_after.mean_after.' + s)}"
              f"<td></td></tr>")
    p.add("</table>")
    p.img("before_after.png", figs["before_after.png"], "NRMSE before and after")
    p.add("</section>")


#: the diagnose summary's candidate fields shown, as words: key -> (column head, unit or how
#: to read it). Other keys stay in metrics.json (``summary.candidates``)
CANDIDATE_COLUMNS = {
    "delta_bic": ("change of BIC", "negative: the effect pays for its parameters"),
    "heldout_delta": ("change on held-out data", "n log(χ² ratio); negative: better"),
    "size_sigmas": ("effect size", "standard errors from zero"),
    "chi2_drop_fit": ("misfit drop, fitted part", "fraction of χ²"),
    "chi2_drop_heldout": ("misfit drop, held-out part", "fraction of χ²"),
    "omega_nrmse": ("speed error with it", "NRMSE"),
}
#: the summary's error keys as words
ERROR_WORDS = {"omega_nrmse": "speed NRMSE", "theta_nrmse": "angle NRMSE",
               "i_nrmse": "current NRMSE"}


def _cand_cell(p: Page, path: str, v) -> str:
    if v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)):
        return p.num(path)
    return f"<td>{_esc(v)}</td>"


def _decision(c: dict) -> str:
    added = "added" if c.get("chosen") else "not added"
    why = c.get("reason") or c.get("status") or ""
    return f"<b>{added}</b>{f': {_esc(why)}' if why else ''}"


def _candidates(p: Page, cands: list[dict]) -> None:
    keys = [k for k in CANDIDATE_COLUMNS if any(k in c for c in cands)]
    heads = "".join(f"<th>{_esc(CANDIDATE_COLUMNS[k][0])}<br><small>"
                    f"{_esc(CANDIDATE_COLUMNS[k][1])}</small></th>" for k in keys)
    p.add(f"<div class='scroll'><table><tr><th>effect</th><th>decision</th>{heads}</tr>")
    for j, c in enumerate(cands):
        cells = "".join(_cand_cell(p, f"summary.candidates.{j}.{k}", c.get(k)) for k in keys)
        p.add(f"<tr><td>{_esc(c.get('effect', ''))}</td><td class='why'>{_decision(c)}</td>"
              f"{cells}</tr>")
    p.add("</table></div>")


def _untestable(p: Page, rows: list) -> None:
    """Effects the fit part supports but no held-out log here can test: not added, and what to
    record so that they can be (diagnose/testable.py)."""
    items = "".join(f"<li><b>{_esc(u.get('effect', ''))}</b>: record {_esc(u.get('record', ''))}"
                    "</li>" for u in rows if isinstance(u, dict))
    if items:
        p.add("<p>Possible, not testable with these logs (not added: no log held out can tell "
              f"them from the parameters the model has):</p><ul>{items}</ul>")


def _summary(p: Page) -> None:
    s = p.m["summary"]
    p.add('<section id="diagnose"><h2>What diagnose found</h2>')
    added = ", ".join(s.get("added", [])) or "nothing significant"
    p.add(f"<p>Added: <b>{_esc(added)}</b>. Structure left in the residual that no catalogue "
          f"effect explains: <b>{'yes' if s.get('unexplained') else 'no'}</b>.</p>")
    _untestable(p, s.get("untestable") or [])
    cands = [c for c in s.get("candidates", []) if isinstance(c, dict)]
    if cands:
        _candidates(p, cands)
    rows = []
    for side, word in (("before", "before diagnose"), ("after", "after diagnose")):
        if isinstance(s.get(side), dict) and s[side]:
            cells = "".join(f"<td>{_esc(ERROR_WORDS.get(k, k.replace('_', ' ')))}</td>"
                            f"{p.num(f'summary.{side}.{k}')}"
                            for k, v in s[side].items() if isinstance(v, (int, float)))
            rows.append(f"<tr><th>{word}</th>{cells}</tr>")
    if rows:
        p.add("<table>" + "".join(rows) + "</table>")
    p.add("</section>")


def _start(p: Page, k: int) -> str:
    """The state the log was simulated from, in words."""
    lg = p.m["logs"][k]
    x0 = lg.get("initial_state")
    if not x0:
        return ""
    b = f"logs.{k}.initial_state"
    rest = " (at rest)" if x0["omega"] == 0 else " (turning)"
    cur = f"i = {p.span(b + '.i')} A, " if "i" in lg["signals"] else ""
    return (f" Simulated from its measured first state: {cur}ω = {p.span(b + '.omega')} "
            f"rad/s{rest}, θ = {p.span(b + '.theta')} rad.")


def _units(lg: dict) -> str:
    """The columns the log held in its own units, and how they map to SI."""
    parts = []
    for c, u in lg.get("logged_units", {}).items():
        off = f" + {u['offset']:.6g}" if u["offset"] else ""
        parts.append(f"{_esc(c)} as <code>{_esc(u['source'])}</code> (SI = logged × "
                     f"{u['scale']:.6g}{off})")
    return f" Logged in its own units: {'; '.join(parts)}; the figures show both." if parts else ""


def _log_sections(p: Page, figs: dict[str, bytes]) -> None:
    for k, lg in enumerate(p.m["logs"]):
        p.add(f'<section id="log-{k}"><h2>Log {_esc(lg["name"])}</h2>')
        kind = f", {_esc(lg['kind'])}" if lg["kind"] else ""
        thr = ""
        if lg["omega_threshold"] is not None:
            thr = f" Near-zero band |ω| &lt; {p.span(f'logs.{k}.omega_threshold')} rad/s."
        blocked = " Rotor blocked: simulated with the rotor held." if lg["blocked"] else ""
        p.add(f"<p><code>{_esc(lg['path'])}</code>: {p.span(f'logs.{k}.n')} samples, "
              f"{p.span(f'logs.{k}.duration')} s at {p.span(f'logs.{k}.rate_hz')} Hz, driven by "
              f"{_esc(lg['drive'])}{kind}.{_start(p, k)}{thr}{blocked}{_units(lg)}</p>")
        about = _why(p.m, lambda n, k=k: n["log_index"] == k)
        if about:
            p.add(f"<p>{about}</p>")
        for f in lg["figures"]:
            p.img(f, figs[f], f"{lg['name']} {f}")
        p.add("</section>")


def _overview(p: Page) -> None:
    m = p.m
    p.add("<section id='overview'><h2>Overview</h2>")
    if m["mean"]:
        cells = "".join(f"<td>{_esc(s.replace('_nrmse', ''))}</td>{p.num('mean.' + s)}"
                        for s in m["mean"])
        p.add(f"<table><tr><th>mean NRMSE</th>{cells}</tr>")
        ba = m.get("before_after")
        if ba:
            cells = "".join(f"<td>{_esc(s.replace('_nrmse', ''))}</td>"
                            f"{p.num('before_after.mean_before.' + s)}"
                            for s in m["mean"] if s in ba["mean_before"])
            p.add(f"<tr><th>before the added effects</th>{cells}</tr>")
        p.add("</table>")
    links = [("notes", "warnings and notes"), ("parameters", "parameters"),
             ("errors", "errors per log and signal")]
    if m.get("before_after"):
        links.append(("before-after", "before and after"))
    if m.get("summary"):
        links.append(("diagnose", "what diagnose found"))
    links += [(f"log-{k}", f"log {lg['name']}") for k, lg in enumerate(m["logs"])]
    p.add("<p>Contents: " + " · ".join(f"<a href='#{a}'>{_esc(t)}</a>" for a, t in links)
          + "</p></section>")


def render(metrics: dict, figs: dict[str, bytes]) -> str:
    """The whole page."""
    p = Page(metrics)
    title = f"pmdcid report: {metrics['model_name']}"
    p.add(f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
          f"<meta name='viewport' content='width=device-width, initial-scale=1'>"
          f"<title>{_esc(title)}</title><style>{CSS}</style></head><body>")
    p.add(f"<h1>{_esc(title)}</h1>")
    p.add(f"<p class='note'>pmdcid {_esc(metrics['version'])}, {_esc(metrics['created'])}. "
          f"{len(metrics['logs'])} log(s). The model is simulated open loop on each log's "
          f"input, from the state the log measured at its first sample (at rest unless it "
          f"starts turning; a blocked rotor held still), and compared with what the log "
          f"measured: <span class='legend-meas'></span> measured, "
          f"<span class='legend-sim'></span> model. All numbers are in "
          f"<code>metrics.json</code>.</p>")
    _overview(p)
    _notes(p)
    _params(p)
    _errors(p, figs)
    if metrics.get("before_after"):
        _before_after(p, figs)
    if metrics.get("summary"):
        _summary(p)
    _log_sections(p, figs)
    p.add("</body></html>")
    return p.text() + "\n"
