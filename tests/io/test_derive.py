"""Speed from angle (zero-phase filter + derivative), angle from speed, --cutoff, units mapping."""


import math

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import REPO

from pmdcid.cli import main
from pmdcid.errors import LogError
from pmdcid.io import ColumnMap, parse_mapping, read_log, write_log
from pmdcid.io.derive import (
    check_cutoff,
    default_cutoff,
    mad_std,
    noise_std,
    position_from_speed,
    speed_from_position,
)

DOCS = REPO / "docs"


def _motion(fs: float, duration: float, amp: float, f: float):
    """Speed amp*sin(2 pi f t) + amp/3 [rad/s] and its exact angle [rad]."""
    t = np.arange(int(duration * fs)) / fs
    w = 2 * np.pi * f
    omega = amp * np.sin(w * t) + amp / 3
    theta = amp * (1 - np.cos(w * t)) / w + amp / 3 * t
    return t, omega, theta


@pytest.mark.parametrize("fs, amp, f", [(1000.0, 10.0, 2.0), (10000.0, 100.0, 5.0),
                                        (200.0, 1.0, 0.5)])
def test_speed_from_clean_angle_has_no_lag(fs, amp, f):
    t, omega, theta = _motion(fs, 4.0, amp, f)
    est = speed_from_position(theta, 1 / fs)
    inner = slice(len(t) // 10, -len(t) // 10)
    err = est[inner] - omega[inner]
    # a lag of one sample alone would give an error of amp*2*pi*f/fs
    assert np.max(np.abs(err)) < 0.05 * amp * 2 * np.pi * f / fs


@pytest.mark.parametrize("counts", [4096, 50000])
def test_speed_from_encoder_counts(counts):
    fs = 1000.0
    t, omega, theta = _motion(fs, 4.0, 20.0, 1.0)
    q = 2 * np.pi / counts
    est = speed_from_position(np.round(theta / q) * q, 1 / fs)
    inner = slice(200, -200)
    rel = np.sqrt(np.mean((est[inner] - omega[inner]) ** 2)) / np.std(omega)
    # quantisation noise q/sqrt(12) differentiated through a 100 Hz band, well under 5 %
    assert rel < 0.05
    # a lower cut-off rejects more of the quantisation noise
    est20 = speed_from_position(np.round(theta / q) * q, 1 / fs, 20.0)
    rel20 = np.sqrt(np.mean((est20[inner] - omega[inner]) ** 2)) / np.std(omega)
    assert rel20 < rel


def test_position_from_speed():
    fs = 500.0
    t, omega, theta = _motion(fs, 3.0, 5.0, 1.5)
    est = position_from_speed(omega, 1 / fs)
    assert est[0] == 0.0
    assert np.max(np.abs(est - theta)) < 1e-4 * np.max(np.abs(theta))


def _write(tmp_path, name, cols, fs=1000.0):
    n = len(next(iter(cols.values())))
    p = tmp_path / name
    write_log(p, np.arange(n) / fs, cols)
    return p


def test_read_log_derives_the_missing_column(tmp_path):
    fs = 1000.0
    t, omega, theta = _motion(fs, 2.0, 10.0, 2.0)
    tau = np.zeros_like(t)
    only_theta = read_log(_write(tmp_path, "a.csv", {"tau": tau, "theta": theta}))
    assert only_theta.derived == {"omega"}
    assert np.allclose(only_theta["omega"], speed_from_position(only_theta["theta"], 1 / fs))
    only_omega = read_log(_write(tmp_path, "b.csv", {"tau": tau, "omega": omega}))
    assert only_omega.derived == {"theta"}
    assert np.max(np.abs(only_omega["theta"] - theta)) < 1e-3 * np.max(theta)
    both = read_log(_write(tmp_path, "c.csv", {"tau": tau, "omega": omega, "theta": theta}))
    assert both.derived == set()
    assert np.array_equal(both["omega"], read_log(tmp_path / "c.csv")["omega"])
    # the user's cut-off reaches the filter
    low = read_log(tmp_path / "a.csv", ColumnMap(cutoff_hz=5.0))
    assert low.cutoff_hz == 5.0
    assert np.allclose(low["omega"], speed_from_position(low["theta"], 1 / fs, 5.0))
    assert not np.allclose(low["omega"], only_theta["omega"])


def test_cutoff_is_checked(tmp_path):
    with pytest.raises(LogError, match="Nyquist"):
        check_cutoff(600.0, 1e-3, "x.csv")
    assert check_cutoff(default_cutoff(1e-3), 1e-3) < 500.0
    assert default_cutoff(1e-2) < 50.0
    fs = 1000.0
    t, omega, theta = _motion(fs, 1.0, 10.0, 2.0)
    p = _write(tmp_path, "a.csv", {"tau": np.zeros_like(t), "theta": theta})
    with pytest.raises(LogError, match="a.csv.*Nyquist"):
        read_log(p, ColumnMap(cutoff_hz=700.0))


def test_cli_cutoff(tmp_path):
    fs = 1000.0
    t, omega, theta = _motion(fs, 1.0, 10.0, 2.0)
    p = _write(tmp_path, "a.csv", {"tau": np.zeros_like(t), "theta": theta})
    model = tmp_path / "m.json"
    model.write_text('{"parameters": {"J": {"value": 0.01}}, "effects": []}')
    run = CliRunner().invoke
    bad = run(main, ["simulate", str(p), "-m", str(model), "-o", str(tmp_path / "o.csv"),
                     "--cutoff", "800"])
    assert bad.exit_code == 1
    assert "Nyquist" in bad.output and "a.csv" in bad.output
    neg = run(main, ["simulate", str(p), "-m", str(model), "-o", str(tmp_path / "o.csv"),
                     "--cutoff", "-5"])
    assert neg.exit_code == 2
    ok = run(main, ["simulate", str(p), "-m", str(model), "-o", str(tmp_path / "o.csv"),
                    "--cutoff", "30"])
    assert ok.exit_code == 0, ok.output


#: the mappings of docs/units.md, with the raw column each is fed from the SI truth
UNIT_CASES = [
    ("omega=speed_rpm*rpm", "speed_rpm", lambda s: s["omega"] * 60 / (2 * np.pi)),
    ("theta=angle_deg*deg", "angle_deg", lambda s: s["theta"] * 180 / np.pi),
    ("theta=encoder*rev/8000", "encoder", lambda s: np.round(s["theta"] / (2 * np.pi) * 8000)),
    ("omega=tacho_V*1000/3*rpm", "tacho_V", lambda s: s["omega"] * 60 / (2 * np.pi) * 3 / 1000),
    ("v=pwm*24/255", "pwm", lambda s: np.round(s["v"] / 24 * 255)),
    ("v=pwm*12/512-12", "pwm", lambda s: np.round(s["v"] / 12 * 512 + 512)),
    ("t=time_ms*ms", "time_ms", lambda s: s["t"] * 1e3),
    ("i=current_mA*mA-0.002", "current_mA", lambda s: (s["i"] + 0.002) * 1e3),
    ("theta=pos_mm*mm", "pos_mm", lambda s: s["theta"] * 1e3),
]


@pytest.mark.parametrize("text, raw, to_raw", UNIT_CASES, ids=[c[0] for c in UNIT_CASES])
def test_units_through_mapping(tmp_path, text, raw, to_raw):
    assert f"`{text}`" in (DOCS / "units.md").read_text()
    fs = 1000.0
    t, omega, theta = _motion(fs, 1.0, 30.0, 2.0)
    v = 6.0 * np.sin(2 * np.pi * t)
    truth = {"t": t, "omega": omega, "theta": theta, "v": v, "i": 0.3 * v}
    canon = text.split("=")[0]
    cols = {k: truth[k] for k in ("v", "i", "omega", "theta") if k != canon}
    p = tmp_path / "raw.csv"
    if canon == "t":
        write_log(p, t * 1e3, cols)
        p.write_text(p.read_text().replace("t,", "time_ms,", 1))
    else:
        write_log(p, t, {**cols, raw: to_raw(truth)})
    log = read_log(p, parse_mapping([text]))
    got = log.t if canon == "t" else log[canon]
    # encoder and PWM counts are quantised: one count of error at most
    tol = {"encoder": 2 * np.pi / 8000, "pwm": 24 / 255}.get(raw, 1e-6 * np.max(np.abs(got)))
    want = truth[canon] - truth[canon][0] if canon == "t" else truth[canon]
    assert np.max(np.abs(got - want)) <= tol


@pytest.mark.parametrize("n", [2, 5, 13, 14, 400])
@pytest.mark.parametrize("cutoff", [3.0, 50.0, 240.0])
def test_lowpass_is_scipys_sosfiltfilt_bit_for_bit(n, cutoff):
    """lowpass keeps the filter's design between calls and runs sosfiltfilt's steps itself:
    the same bits as scipy's sosfiltfilt with the same padding, short signals included."""
    from scipy.signal import butter, sosfiltfilt

    from pmdcid.io.derive import ORDER, lowpass

    x = np.random.default_rng(n).normal(size=n).cumsum()
    ref = sosfiltfilt(butter(ORDER, cutoff, btype="low", fs=1e3, output="sos"), x,
                      padlen=min(3 * ORDER, n - 1))
    for _ in range(2):  # designed, then kept
        np.testing.assert_array_equal(lowpass(x, 1e-3, cutoff), ref)


@pytest.mark.parametrize("n", [2, 14, 400])
def test_both_filter_passes_give_the_same_bits(monkeypatch, n):
    """lowpass runs scipy's compiled sections loop without sosfilt's checks where that private
    name is there, else sosfilt itself: either way the same bits."""
    from pmdcid.io import derive

    if derive._compiled_loop() is None:
        pytest.skip("this scipy has no compiled sections loop under that name")
    x = np.random.default_rng(n).normal(size=n).cumsum()
    got = {}
    for one in (derive._core_sos_pass, derive._public_sos_pass):
        monkeypatch.setattr(derive, "_sos_pass", lambda one=one: one)
        got[one.__name__] = derive.lowpass(x, 1e-3, 40.0)
    np.testing.assert_array_equal(got["_core_sos_pass"], got["_public_sos_pass"])


def _on_another_clock(rng, tk_values, fs: float, n: int):
    """Samples ``values`` taken at jittered instants (up to a fifth of a period late), put on
    the uniform clock ``k/fs`` by linear interpolation, as the MCAP reader puts a measured
    signal on the fastest measurement's grid."""
    tk = np.arange(n) / fs + rng.uniform(0.0, 0.2 / fs, n)
    return np.interp(np.arange(1, n - 1) / fs, tk, tk_values(tk))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noise_of_an_interpolated_quantised_speed_at_rest_half_the_log(seed):
    """A speed read to q = 0.1 rad/s, exactly 0 for the first half (at rest), then moving
    (40 + 30 sin(2 pi t) rad/s, several quanta per sample: its rounding error is white, std
    q/sqrt(12)), sampled late by up to 0.4 ms and interpolated onto a 500 Hz clock. Its noise
    level, the RMS over the log (none at rest), is q/sqrt(12)/sqrt(2) within 20 % (0.92 of it
    measured against the true speed: the interpolation averages neighbours). Before, the MAD
    of the second difference was 0 (the rest) and the smallest step a rounding artefact:
    1e-12 rad/s, which weighed the log 1e20 times (rig1 of the new-user walkthrough: reduced
    chi-square 2e6)."""
    q, fs, n = 0.1, 500.0, 4000

    def speed(t):
        return q * np.round(np.where(t < n / (2 * fs), 0.0, 40 + 30 * np.sin(2 * np.pi * t)) / q)

    x = _on_another_clock(np.random.default_rng(seed), speed, fs, n)
    assert noise_std(x) == pytest.approx(q / math.sqrt(24.0), rel=0.2)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_an_interpolated_held_input_gets_no_noise_from_its_edges(seed):
    """A command held at levels 3 V apart (0, 3, 6, -6, 12 V for 0.2 s each), sampled at 100 Hz
    and interpolated onto a 500 Hz clock: an edge becomes one or more partial steps beside the
    held stretches, which are no noise (an earlier rule read 0.19-1.06 V off such a command)."""
    fs, n = 500.0, 4000
    rng = np.random.default_rng(seed)
    levels = np.repeat(rng.choice([0.0, 3.0, 6.0, -6.0, 12.0], 20), 100)
    tk = np.arange(n // 5) * 5 / fs + rng.uniform(0.0, 0.5 / fs, n // 5)
    x = np.interp(np.arange(1, n - 10) / fs, tk, levels[: tk.size])
    assert noise_std(x) < 0.01 * 3.0


def test_a_quantised_speed_on_its_own_clock_keeps_its_quantum():
    """An encoder-difference speed (4096 counts/rev at 500 Hz: q = 1.53 rad/s) on its own
    clock, at rest for half the log, then 40 + 20 sin(pi t) rad/s: every value is a whole
    number of counts, its noise the quantum's q/sqrt(12). Reading it only where it changes at
    every sample would pick the samples where it jumps (about 3 times as much)."""
    fs, n, cpr = 500.0, 4000, 4096
    t = np.arange(n) / fs
    w = np.where(t < n / (2 * fs), 0.0, 40 + 20 * np.sin(np.pi * t))
    counts = np.floor(np.cumsum(w) / fs / (2 * np.pi) * cpr)
    q = 2 * np.pi / cpr * fs
    x = np.r_[0.0, np.diff(counts)] * 2 * np.pi / cpr * fs
    assert noise_std(x) == pytest.approx(q / math.sqrt(12.0), rel=0.01)


@pytest.mark.parametrize("seed", [1, 2])
def test_a_dithering_quantised_speed_keeps_its_mad_reading(seed):
    """A step log's quantised speed whose repeats are its noise: counts per 10 ms of a 500-line
    encoder x4 behind a 16:1 gear (0.1875 rpm a count), at rest for 8 s, then turning at 14
    rad/s with 0.02 rad/s of jitter, printed in rpm to two decimals (off its lattice by the
    printing), as a real rig's logs are. The MAD of the second difference reads it; reading
    only where it changes (the rule for a speed resting half the log, whose MAD is rounding)
    gave 1.5 times as much here and doubled that real rig's speed noise."""
    rng = np.random.default_rng(seed)
    fs, n, cpr = 100.0, 3000, 500 * 4 * 16
    t = np.arange(n) / fs
    w = np.where(t < 8, 0.0, 14.0 * (1 - np.exp(-np.clip(t - 8, 0, None) / 0.1))
                 + rng.normal(0, 0.02, n))
    counts = np.floor(np.cumsum(w) / fs / (2 * np.pi) * cpr + rng.uniform())
    x = np.round(np.r_[0.0, np.diff(counts) * 60 / cpr * fs], 2) * 2 * np.pi / 60
    mad = mad_std(np.diff(x, 2)) / math.sqrt(6.0)
    steps = np.abs(np.diff(x))
    assert mad > 0 and noise_std(x) == max(mad, float(np.min(steps[steps > 0])) / math.sqrt(12))
