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

from pmdcid.io import read_log, write_log
from pmdcid.report import make_report
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, triangle, truth_model

FIX = Path(__file__).resolve().parents[1] / "fixtures"


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


def _render(page: Path, tmp_path: Path) -> tuple[dict, str]:
    """Load a probed copy of ``page`` in Chromium; the probe's findings and Chromium's stderr."""
    text = page.read_text()
    probed = page.with_name("probed_" + page.name)
    probed.write_text(text.replace("<head>", "<head>" + PROBE, 1))
    proc = subprocess.run(
        [CHROMIUM, *FLAGS, f"--user-data-dir={tmp_path / 'profile'}", "--enable-logging=stderr",
         "--v=0", "--virtual-time-budget=10000", "--dump-dom", probed.as_uri()],
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
