"""The report a person reads at a glance (issue #26): the input above the output, measured and
model told apart by colour and weight, the fit in each legend, the log's own units beside SI,
the warnings beside the numbers they qualify, the diagnose table in words, the header true
about the initial state."""

from __future__ import annotations

import re
from html.parser import HTMLParser

import numpy as np
import pandas as pd
import pytest
from matplotlib.colors import to_rgb

import pmdcid
from pmdcid.report import figures, make_report
from pmdcid.report.compare import compare_log
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, triangle, truth_model

#: the diagnose summary as diagnose writes it (every key of a candidate)
CANDIDATE = {"effect": "stribeck", "delta_bic": -80.0, "omega_nrmse": 0.011, "refit": True,
             "status": "refitted", "reason": "lowers BIC and the held-out error",
             "heldout_delta": -12.3, "screen_gain": 0.3, "round": 1, "chosen": True,
             "size_sigmas": 14.2, "chi2_drop_fit": 0.31, "chi2_drop_heldout": 0.28,
             "heldout_log_rise": 0.01, "starts": 2, "parameters": {"fs": 0.003}}
DZ_NOTE = ("fit-nonlinear: dz is not identifiable from these logs: any dead zone from 0 to "
           "0.008 N m fits; written as the midpoint")
DELAY = ("sensor_delay = 3.2 ms with no current logged: a command applied late looks the same "
         "in voltage and speed")


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """A 4 s triangle logged in PWM counts and rpm, and a model carrying notes."""
    tmp = tmp_path_factory.mktemp("rig")
    rng = np.random.default_rng(26)
    t = np.arange(4000) * 1e-3
    cols, _ = synth_log(t, triangle(t, 1.5, 4.0), {**neutral_values(), **PAPER}, PAPER_NOISE,
                        rng)
    df = pd.DataFrame({"t": t, "pwm": cols["v"] * 255 / 12,
                       "speed_rpm": cols["omega"] * 30 / np.pi, "i": cols["i"]})
    (tmp / "rpm.csv").write_text("# kind: triangle\n" + df.to_csv(index=False))
    log = pmdcid.Log.from_csv(tmp / "rpm.csv", columns={"v": "pwm*12/255",
                                                        "omega": "speed_rpm*rpm"})
    model = truth_model(PAPER, ["sensor_delay"])
    model.set("dz", 0.004, 0.0023, stage="fit-nonlinear")
    model.set("delay", 0.0, stage="diagnose")
    model.extra["notes"] = [{"text": DZ_NOTE, "about": ["dz"], "severity": "warning",
                             "stage": "fit-nonlinear", "log": ""},
                            {"text": f"fit-mechanical: {log.path}: 2 isolated speed spike(s): "
                             "reported, not fitted", "about": [], "severity": "warning",
                             "stage": "fit-mechanical"}]
    return tmp, log, model


def test_overlay_input_on_top_model_told_apart_fit_in_legend_own_units(rig):
    _, log, model = rig
    c = compare_log(log, model, "rpm")
    pool = figures.FigurePool()
    figures.overlay_figure(c, pool)
    (_, axes), = pool._figs.values()
    top, speed = axes[0, 0], axes[1, 0]
    assert top.get_ylabel() == "input voltage [V]"
    assert [a.get_ylabel() for a in top.child_axes] == ["pwm (as logged)"]
    assert [a.get_ylabel() for a in speed.child_axes] == ["speed_rpm (as logged)"]
    meas, sim = speed.lines[:2]
    assert meas.get_linewidth() >= 2 * sim.get_linewidth()  # weight
    rgb_m, rgb_s = np.array(to_rgb(meas.get_color())), np.array(to_rgb(sim.get_color()))
    assert np.ptp(rgb_m) < 0.05 < 0.5 < np.ptp(rgb_s)  # grey against a saturated colour
    assert sim.get_linestyle() == "-"
    legend = [t.get_text() for t in speed.get_legend().get_texts()]
    fit = c.metrics["signals"]["omega"]["fit_percent"]
    assert legend == ["measured", f"model (fit {fit:.1f} %)"]
    secondary = top.child_axes[0]  # 255 PWM counts are 12 V
    assert np.allclose(secondary.get_ylim(), np.array(top.get_ylim()) * 255 / 12)
    assert c.metrics["logged_units"]["v"]["scale"] == pytest.approx(12 / 255)


class _Text(HTMLParser):
    """The page's visible text, and the text of each element with an id."""

    def __init__(self):
        super().__init__()
        self.text, self.by_id, self._open = [], {}, []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if "id" in a:
            self._open.append((tag, a["id"]))
            self.by_id[a["id"]] = ""

    def handle_endtag(self, tag):
        if self._open and self._open[-1][0] == tag:
            self._open.pop()

    def handle_data(self, data):
        self.text.append(data)
        for _, i in self._open:
            self.by_id[i] += data


@pytest.fixture(scope="module")
def page(rig):
    tmp, log, model = rig
    summary = {"added": ["stribeck"], "unexplained": False,
               "candidates": [CANDIDATE, {**CANDIDATE, "effect": "cogging", "chosen": False,
                                          "reason": "no gain on the held-out logs"}],
               "before": {"omega_nrmse": 0.05}, "after": {"omega_nrmse": 0.01},
               "untestable": [{"effect": "quadratic_drag", "record": "steady speeds spanning "
                               "the range", "reason": "possible, not testable with these logs"}],
               "notes": [], "warnings": [DELAY]}
    res = make_report([log], model, tmp / "rep", summary=summary)
    assert len(repr(res)) < 200 and "report.html" in repr(res)  # not the metrics
    p = _Text()
    p.feed(open(res.html_path, encoding="utf-8").read())
    return p, res.metrics


def test_warnings_sit_beside_the_numbers_they_qualify(page):
    p, metrics = page
    assert "dz is not identifiable" in p.by_id["param-dz"]
    assert "57.5" in p.by_id["param-dz"]  # the ± 58 % and why, on one row
    assert "sensor_delay = 3.2 ms" in p.by_id["param-delay"]  # an effect's note: its rows
    assert "dz is not identifiable" not in p.by_id["param-J"]
    listed = p.by_id["notes"]
    assert "warning: fit-nonlinear: dz is not identifiable" in " ".join(listed.split())
    assert DELAY in " ".join(listed.split())
    assert [n["rows"] for n in metrics["notes"]] == [["dz"], [], ["delay"]]
    assert [n["log_index"] for n in metrics["notes"]] == [None, 0, None]
    assert "2 isolated speed spike(s)" in p.by_id["log-0"]


def test_diagnose_table_in_words_and_header_true_about_the_start(page):
    p, metrics = page
    text = " ".join(" ".join(p.text).split())
    for raw in ("delta_bic", "heldout_delta", "size_sigmas", "chi2_drop_fit", "omega_nrmse",
                "screen_gain"):
        assert raw not in text, raw
    diag = " ".join(p.by_id["diagnose"].split())
    assert "change of BIC" in diag and "standard errors from zero" in diag
    assert "not added: no gain on the held-out logs" in diag
    assert ("Possible, not testable with these logs" in diag
            and "quadratic_drag: record steady speeds spanning the range" in diag)
    assert "from rest on each" not in text
    assert "from the state the log measured at its first sample" in text
    x0 = metrics["logs"][0]["initial_state"]
    assert set(x0) == {"i", "omega", "theta"}
    assert re.search(r"Simulated from its measured first state: i = \S+ A, ω = 0 rad/s "
                     r"\(at rest\)", text)


def test_errors_in_the_logs_own_unit_beside_si(page):
    p, metrics = page
    om = metrics["logs"][0]["signals"]["omega"]
    assert om["rms_logged"] == pytest.approx(om["rms"] * 30 / np.pi)
    assert "speed_rpm" in p.by_id["errors"]
    assert "omega as speed_rpm (SI = logged × 0.10472)" in " ".join(p.by_id["log-0"].split())
