"""`pmdcid report`: metrics on constructed cases, the report on fixtures and synthetic logs."""

import json
import re
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.io import read_log, write_log
from pmdcid.report import make_report
from pmdcid.report.html import get_path
from pmdcid.report.metrics import Z99, residual_correlations, signal_metrics, speed_threshold
from pmdcid.synth import PAPER, PAPER_NOISE, synth_log, triangle, truth_model

FIX = FIXTURES
STRIBECK = {"fs": 3e-3, "ws": 0.15}


# ---- metrics on constructed cases ---------------------------------------------------------

def test_nrmse_zero_when_simulation_equals_measurement(rng):
    meas = rng.normal(size=2000)
    u = rng.normal(size=2000)
    m = signal_metrics(meas.copy(), meas, u, np.abs(meas) < 0.1)
    assert m["nrmse"] == 0.0
    assert m["fit_percent"] == 100.0
    assert m["rms"] == 0.0 and m["max_abs"] == 0.0
    assert m["low_speed"]["rms"] == 0.0 and m["high_speed"]["rms"] == 0.0


def test_nrmse_of_known_offset_and_regime_split(rng):
    meas = np.sin(np.linspace(0, 6 * np.pi, 3000)) * 2.0
    low = np.abs(meas) < speed_threshold(meas)
    err = np.where(low, 0.1, 0.0)  # error only near zero speed
    m = signal_metrics(meas + err, meas, rng.normal(size=3000), low)
    sd = np.std(meas)
    assert m["nrmse"] == pytest.approx(0.1 * np.sqrt(low.mean()) / sd, rel=1e-9)
    assert m["fit_percent"] == pytest.approx(100 * (1 - m["nrmse"]), rel=1e-12)
    assert m["max_abs"] == pytest.approx(0.1)
    assert m["low_speed"]["nrmse"] == pytest.approx(0.1 / sd, rel=1e-9)
    assert m["high_speed"]["rms"] == 0.0
    assert m["low_speed"]["fraction"] == pytest.approx(low.mean())
    # the threshold is 5 % of the largest |speed|
    assert speed_threshold(meas) == pytest.approx(0.05 * np.max(np.abs(meas)))


def test_resid_white_residual_inside_bands_and_input_leak_outside(rng):
    n = 20000
    u = rng.normal(size=n)
    e = rng.normal(size=n)
    r = residual_correlations(e, u)
    assert r["auto"]["band"] == pytest.approx(Z99 / np.sqrt(n))
    assert r["auto"]["r"][0] == pytest.approx(1.0)
    # 25 lags at 99 %: a white residual independent of u rarely leaves the bands
    assert r["auto"]["outside"] <= 3 and r["cross"]["outside"] <= 3
    # a residual made of the input delayed by 3 samples: one cross-correlation lag far outside
    leak = np.roll(u, 3) + 0.1 * e
    r2 = residual_correlations(leak, u)
    k = r2["cross"]["lags"].index(3)
    assert r2["cross"]["r"][k] > 0.9
    assert r2["cross"]["outside"] >= 1
    # a coloured residual (random walk) is flagged by the autocorrelation
    assert residual_correlations(np.cumsum(e), u)["auto"]["outside"] == 25


# ---- the report on logs -------------------------------------------------------------------

def _short_triangle(tmp_path, rng, vals, name="tri.csv", torque=False, drop=()):
    t = np.arange(16000) * 1e-3
    amp = 0.02 if torque else 1.5
    cols, _ = synth_log(t, triangle(t, amp, 8.0), vals, PAPER_NOISE, rng, torque_driven=torque)
    for c in drop:
        cols.pop(c, None)
    write_log(tmp_path / name, t, cols, {"kind": "triangle"})
    return read_log(tmp_path / name)


class _Cells(HTMLParser):
    """Collects (data-m path, text) of every numeric cell and the sections' ids."""

    def __init__(self):
        super().__init__()
        self.cells, self.sections, self.imgs = [], [], 0
        self._path, self._text = None, ""
        self.num_cells_without_path = 0

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "section":
            self.sections.append(a.get("id"))
        if tag == "img":
            self.imgs += 1
            assert a["src"].startswith("data:image/png;base64,")
        if "data-m" in a:
            self._path, self._text = a["data-m"], ""
        elif tag == "td" and a.get("class") == "num":
            self.num_cells_without_path += 1

    def handle_data(self, data):
        if self._path is not None:
            self._text += data

    def handle_endtag(self, tag):
        if self._path is not None and tag in ("td", "span"):
            self.cells.append((self._path, self._text.strip()))
            self._path = None


def _check_numbers_match(html_text: str, metrics: dict) -> _Cells:
    p = _Cells()
    p.feed(html_text)
    assert p.num_cells_without_path == 0
    assert len(p.cells) > 20
    for path, text in p.cells:
        v = get_path(metrics, path)
        if v is None:
            assert text == "–", path
        else:
            assert float(text) == pytest.approx(v, rel=1e-3, abs=1e-300), path
    return p


def test_report_effects_before_after_and_numbers(tmp_path, rng, paper_values):
    vals = {**paper_values, **STRIBECK}
    log = _short_triangle(tmp_path, rng, vals)
    model = truth_model({**PAPER, **STRIBECK}, ["stribeck"])
    model.set("J", PAPER["J"], stderr=2e-6, stage="fit-nonlinear")
    summary = {"added": ["stribeck"], "unexplained": False,
               "candidates": [{"effect": "stribeck", "delta_bic": -812.4, "omega_nrmse": 0.011}],
               "before": {"omega_nrmse": 0.094}, "after": {"omega_nrmse": 0.011}}
    res = make_report([log], model, tmp_path / "rep", summary=summary)
    out = tmp_path / "rep"
    assert Path(res.html_path) == out / "report.html"
    on_disk = json.loads((out / "metrics.json").read_text())
    assert on_disk == json.loads(json.dumps(res.metrics))
    for f in on_disk["figures"]:
        assert (out / f).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    html_text = (out / "report.html").read_text()
    cells = _check_numbers_match(html_text, on_disk)
    assert {"parameters", "errors", "before-after", "diagnose", "log-0"} <= set(cells.sections)
    assert cells.imgs == len(on_disk["figures"])
    lg = on_disk["logs"][0]
    assert set(lg["signals"]) == {"omega", "theta", "i"}
    # the true model: the speed residual is the sensor noise (4 mrad/s)
    assert lg["signals"]["omega"]["rms"] == pytest.approx(PAPER_NOISE.omega, rel=0.1)
    # without the Stribeck term the model is worse, most of all near zero speed
    ba = on_disk["before_after"]
    assert ba["effects"] == ["stribeck"]
    assert ba["after"][0]["omega"] < 0.5 * ba["before"][0]["omega"]
    assert ba["after"][0]["i"] == pytest.approx(ba["before"][0]["i"], rel=1e-6)
    assert on_disk["parameters"]["J"]["stderr"] == 2e-6
    assert on_disk["parameters"]["J"]["unit"] == "kg m^2"
    assert on_disk["summary"]["candidates"][0]["delta_bic"] == -812.4


def test_report_torque_driven_and_without_current(tmp_path, rng, paper_values):
    log = _short_triangle(tmp_path, rng, paper_values, "tau.csv", torque=True)
    assert log.drive == "tau" and not log.has("i")
    model = truth_model({"J": PAPER["J"], "bv": PAPER["bv"], "bc": PAPER["bc"]})
    res = make_report([log], model, tmp_path / "rep")
    lg = res.metrics["logs"][0]
    assert set(lg["signals"]) == {"omega", "theta"}
    assert lg["drive"] == "tau"
    assert res.metrics["before_after"] is None
    _check_numbers_match(Path(res.html_path).read_text(), res.metrics)
    # a voltage log lacking i (and theta): speed and derived angle only
    log2 = _short_triangle(tmp_path, rng, paper_values, "noi.csv", drop=("i", "theta"))
    res2 = make_report([log2], truth_model(PAPER), tmp_path / "rep2")
    sig = res2.metrics["logs"][0]["signals"]
    assert set(sig) == {"omega", "theta"} and sig["theta"]["derived"]


def test_report_on_fixtures_blocked_and_step(tmp_path):
    logs = [read_log(FIX / "paper" / "blocked_1.0V.csv"), read_log(FIX / "paper" / "step_1.0V.csv")]
    res = make_report(logs, truth_model(PAPER), tmp_path / "rep")
    blocked, step = res.metrics["logs"]
    # blocked rotor: only the current is compared, with the rotor held in the simulation
    assert blocked["blocked"] and set(blocked["signals"]) == {"i"}
    assert blocked["signals"]["i"]["rms"] == pytest.approx(PAPER_NOISE.i, rel=0.15)
    assert step["signals"]["omega"]["rms"] == pytest.approx(PAPER_NOISE.omega, rel=0.15)
    assert step["signals"]["omega"]["fit_percent"] > 95
    # a wrong inertia shows up as a larger error than the noise
    wrong = truth_model({**PAPER, "J": 2 * PAPER["J"]})
    res2 = make_report(logs[1:], wrong, tmp_path / "rep2")
    assert res2.metrics["logs"][0]["signals"]["omega"]["rms"] > 3 * PAPER_NOISE.omega


def test_report_cli(tmp_path):
    model = tmp_path / "m.json"
    model.write_text(json.dumps({"parameters": PAPER, "effects": []}))
    summ = tmp_path / "s.json"
    summ.write_text(json.dumps({"added": [], "candidates": [], "unexplained": False,
                                "before": {"omega_nrmse": 0.02}, "after": {"omega_nrmse": 0.02}}))
    r = CliRunner().invoke(main, ["report", str(FIX / "paper" / "step_2.0V.csv"), "-m",
                                  str(model), "-o", str(tmp_path / "out"), "--summary", str(summ)])
    assert r.exit_code == 0, r.output
    assert re.search(r"wrote .*report\.html", r.output)
    m = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert m["summary"]["before"]["omega_nrmse"] == 0.02
    bad = tmp_path / "bad.json"
    bad.write_text("[1, 2]")
    r = CliRunner().invoke(main, ["report", str(FIX / "paper" / "step_2.0V.csv"), "-m",
                                  str(model), "-o", str(tmp_path / "o2"), "--summary", str(bad)])
    assert r.exit_code == 1 and "bad.json" in r.output
    assert not (tmp_path / "o2").exists()


def test_zoom_window_finds_the_crossing_not_the_noise(rng):
    from pmdcid.report.figures import zoom_window

    t = np.arange(3000) * 1e-3
    slow = np.where(t > 1.0, 0.1 * (t - 1.0), 0.0)  # at most 0.2 rad/s
    noisy = slow + rng.normal(0, 0.005, len(t))  # noise at rest above the 5 % band
    a, b, what = zoom_window(t, noisy, speed_threshold(noisy))
    assert what == "breakaway from rest" and t[a] < 1.0 < t[b - 1]
    om = np.cos(2 * np.pi * t / 2.0) + rng.normal(0, 0.005, len(t))  # crosses zero at 0.5 s
    a, b, what = zoom_window(t, om, speed_threshold(om))
    assert what == "zero-speed crossing" and t[a] < 0.5 < t[b - 1] and b - a < 600


def test_report_shows_the_diagnose_record_of_the_model(tmp_path):
    model = truth_model(PAPER)
    model.extra["fits"] = {"diagnose": {"logs": ["x.csv"], "added": ["stribeck"]}}
    res = make_report([read_log(FIX / "paper" / "step_1.5V.csv")], model, tmp_path / "r")
    assert res.metrics["summary"]["added"] == ["stribeck"]
    assert 'id="diagnose"' in Path(res.html_path).read_text()


def test_blockwise_covariance_equals_direct_sum(rng, monkeypatch):
    from pmdcid.report import metrics

    for n, nlag in ((1000, 40), (1030, 100)):  # the second ends on a block shorter than nlag
        a, b = rng.normal(size=n), rng.normal(size=n)
        direct = np.array([np.dot(a[: n - k], b[k:]) for k in range(nlag)]) / n
        for block in (64, 1 << 17):  # many blocks and one block
            monkeypatch.setattr(metrics, "BLOCK", block)
            assert np.allclose(metrics._cov_lags(a, b, nlag), direct, rtol=1e-10, atol=1e-12)


def test_report_never_overwrites_an_input(tmp_path):
    src = FIX / "paper" / "step_1.0V.csv"
    log_path = tmp_path / "metrics.json"  # a log that happens to bear an output's name
    log_path.write_bytes(src.read_bytes())
    before = log_path.read_bytes()
    from pmdcid.errors import LogError

    with pytest.raises(LogError, match="overwrite"):
        make_report([read_log(log_path)], truth_model(PAPER), tmp_path)
    assert log_path.read_bytes() == before
    assert not (tmp_path / "report.html").exists()


def test_report_cli_on_real_torque_driven_log_with_mapping(tmp_path):
    """EMPS (real, a linear axis driven by force; fixtures/emps/CITATION.md): columns mapped
    from the command line, speed derived from the angle, no current."""
    model = tmp_path / "emps.json"
    # parameters of the order fit-nonlinear gives on the estimation file [kg, N s/m, N, N]
    model.write_text(json.dumps({"parameters": {"J": 90.1, "bv": 180.0, "bc": 23.2,
                                                "tau0": -3.38}, "effects": ["torque_offset"]}))
    log = FIX.parents[1] / "shared" / "data" / "emps" / "emps_train_DATA_EMPS.csv"
    if not log.exists():
        pytest.skip(f"EMPS data not under {log.parent}")
    r = CliRunner().invoke(main, ["report", str(log), "-m", str(model), "-o", str(tmp_path / "o"),
                                  "-c", "t=t_s", "-c", "tau=force_N", "-c", "theta=qm_meas_m"])
    assert r.exit_code == 0, r.output
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    lg = m["logs"][0]
    assert lg["drive"] == "tau" and set(lg["signals"]) == {"omega", "theta"}
    assert lg["signals"]["omega"]["derived"] and not lg["signals"]["theta"]["derived"]
    assert lg["signals"]["theta"]["fit_percent"] > 90
    # without its load-torque offset the same model is worse on the angle
    ba = m["before_after"]
    assert ba["effects"] == ["torque_offset"]
    assert ba["after"][0]["theta"] < ba["before"][0]["theta"]


def test_report_on_a_rotor_that_never_moves(tmp_path, paper_values):
    """Noise-free log below breakaway: speed and angle are constant (std 0, NRMSE undefined)."""
    t = np.arange(2000) * 1e-3
    cols, _ = synth_log(t, np.full(len(t), 0.05), paper_values, PAPER_NOISE, None)
    write_log(tmp_path / "still.csv", t, cols)
    res = make_report([read_log(tmp_path / "still.csv")], truth_model(PAPER), tmp_path / "r")
    sig = res.metrics["logs"][0]["signals"]
    assert sig["omega"]["nrmse"] is None and sig["omega"]["fit_percent"] is None
    assert sig["omega"]["rms"] == 0.0
    assert sig["i"]["nrmse"] < 1e-6  # the CSV keeps 9 significant digits
    _check_numbers_match(Path(res.html_path).read_text(), res.metrics)


def test_a_reversed_speed_is_said_by_report_and_refused_by_diagnose(tmp_path, rng, paper_values):
    """A speed sensor counting the other way: report warns in words (stderr and the page's
    notes); diagnose refuses before it refits friction to hold the rotor back."""
    import warnings

    from pmdcid.diagnose.entry import diagnose_logs
    from pmdcid.errors import FitError

    log = _short_triangle(tmp_path, rng, paper_values, drop=("i",))
    cols = {c: -np.asarray(log[c]) for c in ("omega", "theta")}
    write_log(tmp_path / "rev.csv", log.t, {"v": log.u, **cols})
    rev = read_log(tmp_path / "rev.csv")
    model = truth_model(paper_values)
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        res = make_report([rev], model, tmp_path / "rep")
    assert any("runs against the model's" in str(w.message) for w in said)
    assert any("runs against" in n["text"] for n in res.metrics["notes"])
    with pytest.raises(FitError, match="rev.csv: the measured speed runs against"):
        diagnose_logs([rev], model)
    with warnings.catch_warnings(record=True) as said:  # the right way round: no word
        warnings.simplefilter("always")
        res = make_report([log], model, tmp_path / "rep2")
    assert not any("runs against" in str(w.message) for w in said)
    assert not any("runs against" in n["text"] for n in res.metrics["notes"])

