"""report.html in a real browser (headless Chromium): no broken image, no console error, no
empty section. Skipped when Chromium is not installed (``apt-get install chromium``)."""

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from repo_paths import FIXTURES

from pmdcid.io import read_log, write_log
from pmdcid.report import make_report
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, triangle, truth_model

FIX = FIXTURES


def _chromium() -> str | None:
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return "/usr/bin/chromium" if os.access("/usr/bin/chromium", os.X_OK) else None


CHROMIUM = _chromium()
pytestmark = [
    pytest.mark.browser,
    pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium is not installed "
                       "(apt-get install chromium): the browser check of report.html is skipped"),
]

#: runs first in the page: records errors, then on load writes what it found into the DOM
PROBE = """<script>
(function () {
  var errors = [];
  var orig = console.error;
  console.error = function () { errors.push(Array.from(arguments).join(' '));
                                 orig.apply(console, arguments); };
  window.addEventListener('error', function (ev) {
    errors.push(ev.message || ('failed to load ' + (ev.target && ev.target.tagName)));
  }, true);
  window.addEventListener('load', function () {
    var imgs = Array.from(document.images);
    var broken = imgs.filter(function (i) { return !i.complete || i.naturalWidth === 0; });
    var sections = Array.from(document.querySelectorAll('section'));
    var empty = sections.filter(function (s) {
      var c = s.cloneNode(true);
      c.querySelectorAll('h2').forEach(function (h) { h.remove(); });
      return c.textContent.trim() === '' && c.querySelectorAll('img,table').length === 0;
    }).map(function (s) { return s.id; });
    var out = document.createElement('pre');
    out.id = 'pmdcid-probe';
    out.textContent = JSON.stringify({images: imgs.length, broken: broken.length,
      sections: sections.length, empty: empty, errors: errors,
      widths: imgs.map(function (i) { return i.naturalWidth; })});
    document.body.appendChild(out);
  });
})();
</script>"""

FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]


def _render(page: Path, tmp_path: Path, probe: str = PROBE,
            size: str = "1200,2000") -> tuple[dict, str]:
    """Load a probed copy of ``page`` in Chromium (a window ``size`` wide and high); the
    probe's findings and Chromium's stderr."""
    text = page.read_text()
    probed = page.with_name("probed_" + page.name)
    probed.write_text(text.replace("<head>", "<head>" + probe, 1))
    proc = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr",
         "--v=0", "--virtual-time-budget=10000", f"--window-size={size}", "--dump-dom",
         probed.as_uri()],
        capture_output=True, text=True, timeout=120)
    m = re.search(r'<pre id="pmdcid-probe">(.*?)</pre>', proc.stdout, re.S)
    assert m, f"the page did not finish loading in Chromium: {proc.stderr[-2000:]}"
    return json.loads(html.unescape(m.group(1))), proc.stderr


def _console_errors(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if "CONSOLE" in ln or "Uncaught" in ln]


def _small_report(tmp_path: Path) -> Path:
    rng = np.random.default_rng(7)
    vals = {**neutral_values(), **PAPER, "fs": 3e-3, "ws": 0.15}
    t = np.arange(12000) * 1e-3
    cols, _ = synth_log(t, triangle(t, 1.5, 6.0), vals, PAPER_NOISE, rng)
    write_log(tmp_path / "tri.csv", t, cols, {"kind": "triangle"})
    logs = [read_log(tmp_path / "tri.csv"), read_log(FIX / "paper" / "blocked_1.0V.csv")]
    model = truth_model({**PAPER, "fs": 3e-3, "ws": 0.15}, ["stribeck"])
    summary = {"added": ["stribeck"], "unexplained": False,
               "candidates": [{"effect": "stribeck", "delta_bic": -80.0}],
               "before": {"omega_nrmse": 0.05}, "after": {"omega_nrmse": 0.01}}
    return Path(make_report(logs, model, tmp_path / "rep", summary=summary).html_path)


def test_report_renders_in_chromium(tmp_path):
    page = _small_report(tmp_path)
    found, stderr = _render(page, tmp_path)
    nfig = len(json.loads((page.parent / "metrics.json").read_text())["figures"])
    assert found["images"] == nfig and found["broken"] == 0, found
    assert all(w > 300 for w in found["widths"]), found["widths"]
    assert found["sections"] >= 6 and found["empty"] == [], found
    assert found["errors"] == [], found["errors"]
    assert _console_errors(stderr) == []
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile2'}",
                    f"--screenshot={shot}", "--window-size=1200,2000", page.as_uri()],
                   capture_output=True, timeout=120)
    assert shot.stat().st_size > 10000


def test_browser_check_catches_a_broken_page(tmp_path):
    """The check itself can fail: a broken image, an empty section and a console error."""
    page = tmp_path / "bad.html"
    page.write_text("<!DOCTYPE html><html><head><meta charset='utf-8'></head><body>"
                    "<section id='a'><h2>A</h2><img src='data:image/png;base64,AAAA'></section>"
                    "<section id='b'><h2>B</h2> </section>"
                    "<script>console.error('boom')</script></body></html>")
    found, stderr = _render(page, tmp_path)
    assert found["broken"] == 1
    assert found["empty"] == ["b"]
    assert any("boom" in e for e in found["errors"])
    assert any("boom" in ln for ln in _console_errors(stderr))


#: on load: every element reaching past the window's right edge (outside a horizontally
#: scrolling box), each scrolling box that has to scroll, and where the warnings are
LAYOUT = """<script>
window.addEventListener('load', function () {
  var W = document.documentElement.clientWidth;
  var wide = Array.from(document.querySelectorAll('body *')).filter(function (e) {
    return !e.closest('.scroll') && e.getBoundingClientRect().right > W + 0.5;
  }).map(function (e) { return e.tagName + '#' + (e.id || '') + '.' + e.className; });
  var scrolled = Array.from(document.querySelectorAll('.scroll')).filter(function (e) {
    return e.scrollWidth > e.clientWidth + 1; }).map(function (e) {
    return e.closest('section').id; });
  var notes = document.getElementById('notes'), params = document.getElementById('parameters');
  var dz = document.getElementById('param-dz');
  var out = document.createElement('pre');
  out.id = 'pmdcid-probe';
  out.textContent = JSON.stringify({width: W, page: document.documentElement.scrollWidth,
    wide: wide, scrolled: scrolled,
    notes_top: notes ? notes.getBoundingClientRect().top : null,
    notes_height: notes ? notes.getBoundingClientRect().height : 0,
    notes_text: notes ? notes.textContent : '',
    params_top: params.getBoundingClientRect().top,
    dz_text: dz ? dz.textContent : ''});
  document.body.appendChild(out);
});
</script>"""


def _readable_report(tmp_path: Path) -> Path:
    """The small report with a diagnose summary as diagnose writes it (every candidate key) and
    a model carrying the dead zone's caveat."""
    page = _small_report(tmp_path)
    logs = [read_log(tmp_path / "tri.csv"), read_log(FIX / "paper" / "blocked_1.0V.csv")]
    model = truth_model({**PAPER, "fs": 3e-3, "ws": 0.15}, ["stribeck"])
    model.set("dz", 0.004, 0.0023, stage="fit-nonlinear")
    model.extra["notes"] = [{"text": "fit-nonlinear: dz is not identifiable from these logs: "
                             "any dead zone from 0 to 0.008 N m fits; written as the midpoint",
                             "about": ["dz"], "severity": "warning", "stage": "fit-nonlinear",
                             "log": ""}]
    cand = {"effect": "stribeck", "delta_bic": -812.4, "omega_nrmse": 0.011, "refit": True,
            "status": "refitted", "reason": "lowers BIC and the held-out error",
            "heldout_delta": -120.5, "screen_gain": 0.3, "round": 1, "chosen": True,
            "size_sigmas": 14.2, "chi2_drop_fit": 0.31, "chi2_drop_heldout": 0.28,
            "heldout_log_rise": 0.01, "starts": 2, "parameters": {"fs": 0.003, "ws": 0.15}}
    summary = {"added": ["stribeck"], "unexplained": False,
               "candidates": [cand, {**cand, "effect": "quadratic_drag", "chosen": False,
                                     "reason": "does not lower the held-out error"}],
               "before": {"omega_nrmse": 0.05, "theta_nrmse": 0.04},
               "after": {"omega_nrmse": 0.01, "theta_nrmse": 0.008},
               "warnings": ["reduced chi-square 10.3 >> 1: the model leaves structure"]}
    return Path(make_report(logs, model, page.parent.parent / "rep2",
                            summary=summary).html_path)


def test_report_fits_the_window_and_shows_the_warnings_first(tmp_path):
    """A 900 px window (a laptop's half screen): no element, table included, is wider."""
    width = 900
    page = _readable_report(tmp_path)
    found, _ = _render(page, tmp_path, LAYOUT, f"{width},1600")
    assert found["width"] <= width and found["page"] <= found["width"], found
    assert found["wide"] == [], found["wide"]
    assert found["scrolled"] == [], found["scrolled"]  # the tables fit without scrolling
    assert found["notes_height"] > 40 and found["notes_top"] < found["params_top"]
    assert "warning: reduced chi-square 10.3 >> 1" in " ".join(found["notes_text"].split())
    assert "dz is not identifiable" in found["dz_text"]


def test_screenshot_shows_the_warnings_in_their_colour(tmp_path):
    """In the picture a reader sees: the first screen holds the warnings, in their colour."""
    from PIL import Image

    page = _readable_report(tmp_path)
    shot = tmp_path / "top.png"
    subprocess.run([CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile3'}",
                    f"--screenshot={shot}", "--window-size=1000,900", page.as_uri()],
                   capture_output=True, timeout=120)
    img = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    assert img.shape[:2] == (900, 1000)
    warn = np.all(np.abs(img - np.array([0x8a, 0x3c, 0x00])) < 40, axis=2)  # .sev-warning
    rows = np.flatnonzero(warn.sum(axis=1) > 3)
    assert len(rows) > 10, "no warning text on the first screen"
