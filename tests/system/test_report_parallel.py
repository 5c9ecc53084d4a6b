"""The report's figures drawn with a worker process (report/parallel.py, issue #16): the same
bytes as the serial path, a complete report whatever the worker does, no process left behind."""

import multiprocessing
import os
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from repo_paths import REPO

from pmdcid.io import read_log, write_log
from pmdcid.io.build import as_mapping
from pmdcid.report import figures, make_report, parallel
from pmdcid.simulate import neutral_values
from pmdcid.synth import PAPER, PAPER_NOISE, step, synth_log, triangle, truth_model

ROOT = REPO


def _logs(tmp_path, rng):
    """Three short logs of three kinds (triangle, step, blocked rotor): 8 figures. The
    triangle's speed is logged in rpm (its figures carry an axis in the log's own unit)."""
    vals = {**neutral_values(), **PAPER}
    out = []
    for name, n, kind, amp in (("tri", 4000, "triangle", 1.5), ("step", 1500, "step", 1.0),
                               ("blk", 800, "blocked", 1.0)):
        t = np.arange(n) * 1e-3
        if kind == "triangle":
            u = triangle(t, amp, 2.0)
        else:
            u = step(t, amp, 0.2) if kind == "step" else np.full(n, amp)
        cols, _ = synth_log(t, u, vals, PAPER_NOISE, rng, blocked=kind == "blocked")
        mapping = None
        if kind == "triangle":
            cols["speed_rpm"] = cols.pop("omega") * 30 / np.pi
            mapping = as_mapping({"omega": "speed_rpm*rpm"})
        write_log(tmp_path / f"{name}.csv", t, cols, {"kind": kind})
        out.append(read_log(tmp_path / f"{name}.csv", mapping))
    assert out[0].sources["omega"][0] == "speed_rpm"
    return out


def _pngs(out_dir: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(out_dir.glob("*.png"))}


@pytest.fixture
def two_cpus(monkeypatch):
    """A spare CPU whatever the machine (and PMDCID_THREADS) says."""
    from pmdcid.runtime import cpus

    monkeypatch.setattr(cpus, "workers", lambda: 2)


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    """The logs, the model, and the serial report's PNGs (PMDCID_THREADS=1)."""
    tmp = tmp_path_factory.mktemp("serial")
    logs = _logs(tmp, np.random.default_rng(16))
    model = truth_model({**PAPER, "fs": 3e-3, "ws": 0.15}, effects=["stribeck"])
    mp = pytest.MonkeyPatch()
    mp.setenv("PMDCID_THREADS", "1")
    try:
        make_report(logs, model, tmp / "out")
    finally:
        mp.undo()
    pngs = _pngs(tmp / "out")
    assert len(pngs) == 2 * len(logs) + 2  # overlays, residuals, fit, before/after
    return logs, model, pngs


def _count_main_draws(monkeypatch) -> list:
    """Patch the caller's draw (a worker keeps its own) to record what the caller drew."""
    drawn = []
    real = parallel.draw

    def spy(job, pool):
        drawn.append(job.name)
        return real(job, pool)

    monkeypatch.setattr(parallel, "draw", spy)
    return drawn


def _caller_waits_for_the_worker(monkeypatch, claims: int, must: bool) -> None:
    """Patch the caller's claim to wait (at most 120 s) until the worker has claimed ``claims``
    figures: ``must``, fail if it never does; else give up when a worker has died."""
    real_claim = parallel.FigureDrawer._claim

    def wait(self, n):
        deadline = time.monotonic() + 120
        while self._counter is not None and self._counter.value < claims:
            if must:
                assert time.monotonic() < deadline, "the worker never claimed a figure"
            elif time.monotonic() > deadline or not all(p.is_alive() for p in self._procs):
                break
            time.sleep(0.01)
        return real_claim(self, n)

    monkeypatch.setattr(parallel.FigureDrawer, "_claim", wait)


def test_worker_draws_the_serial_bytes(serial, two_cpus, monkeypatch, tmp_path):
    logs, model, want = serial
    drawn = _count_main_draws(monkeypatch)
    _caller_waits_for_the_worker(monkeypatch, 1, must=True)
    make_report(logs, model, tmp_path / "par")
    assert multiprocessing.active_children() == []
    got = _pngs(tmp_path / "par")
    assert sorted(got) == sorted(want)
    assert len(drawn) < len(want)  # the worker drew some ...
    for name in want:  # ... and every file is the serial path's, byte for byte
        assert got[name] == want[name], name


_real_overlay, _real_residual, _real_fit = (figures.overlay_figure, figures.residual_figure,
                                           figures.fit_figure)


def _dies_in_a_worker(cmp, pool=None):
    if multiprocessing.parent_process() is not None:
        os._exit(3)  # the worker dies holding a claimed figure
    return _real_overlay(cmp, pool)


def _fails_in_a_worker(cmp, pool=None):
    if multiprocessing.parent_process() is not None:
        raise RuntimeError("only in the worker")
    return _real_residual(cmp, pool)


@pytest.mark.parametrize("how", ["start", "dies", "fails", "unpicklable"])
def test_a_failing_worker_still_gives_the_whole_report(serial, two_cpus, monkeypatch, tmp_path,
                                                       how):
    logs, model, want = serial
    if how == "start":
        def no_process(proc):
            raise OSError("no process today")
        monkeypatch.setattr(parallel, "_start_quietly", no_process)
    elif how == "dies":
        monkeypatch.setattr(figures, "overlay_figure", _dies_in_a_worker)
    elif how == "fails":
        monkeypatch.setattr(figures, "residual_figure", _fails_in_a_worker)
    else:  # a job the worker cannot be sent: the caller draws everything
        monkeypatch.setattr(figures, "fit_figure", lambda rows: _real_fit(rows))
    if how in ("dies", "fails"):  # let the worker take figures first
        _caller_waits_for_the_worker(monkeypatch, 3, must=False)
    make_report(logs, model, tmp_path / "out")
    assert multiprocessing.active_children() == []
    got = _pngs(tmp_path / "out")
    assert sorted(got) == sorted(want)
    for name in want:
        assert got[name] == want[name], name


def test_a_figure_that_fails_everywhere_fails_the_report_as_serially(serial, two_cpus,
                                                                      monkeypatch, tmp_path):
    logs, model, _ = serial

    def broken(cmp, pool=None):
        raise ValueError("cannot draw this")

    monkeypatch.setattr(figures, "overlay_figure", broken)
    with pytest.raises(ValueError, match="cannot draw this"):
        make_report(logs, model, tmp_path / "out")
    assert multiprocessing.active_children() == []
    assert not (tmp_path / "out").exists()


def test_serial_when_one_cpu_or_few_figures(monkeypatch):
    from pmdcid.runtime import cpus

    monkeypatch.setattr(cpus, "workers", lambda: 1)
    assert parallel.spare_workers(100) == 0
    monkeypatch.setattr(cpus, "workers", lambda: 8)
    assert parallel.spare_workers(parallel.MIN_JOBS - 1) == 0
    assert parallel.spare_workers(parallel.MIN_JOBS) == 1
    assert parallel.spare_workers(100) == parallel.MAX_WORKERS


def test_a_lock_held_by_a_dead_process_does_not_hang_the_claim(monkeypatch):
    ctx = multiprocessing.get_context("spawn")
    counter = ctx.Value("q", 5)
    held, done = threading.Event(), threading.Event()

    def hold():  # as if a worker had died inside its claim
        with counter.get_lock():
            held.set()
            done.wait()

    holder = threading.Thread(target=hold)
    holder.start()
    held.wait()
    monkeypatch.setattr(parallel, "LOCK_WAIT", 0.01)
    try:
        assert parallel._take(counter, 10, lambda: True) == parallel.STUCK
    finally:
        done.set()
        holder.join()
    assert parallel._take(counter, 10, lambda: True) == 5
    assert counter.value == 6
    counter.value = 10
    assert parallel._take(counter, 10, lambda: False) is None


@pytest.mark.skipif(len(os.sched_getaffinity(0)) < 2, reason="needs two CPUs for a worker")
def test_a_script_without_a_main_guard_runs_once(tmp_path):
    """The spawn worker does not import the caller's __main__ (which would run it again)."""
    script = tmp_path / "unguarded.py"
    files = [str(ROOT / "fixtures" / "hidden" / f"step_{v}V.csv") for v in ("0.5", "1.0", "1.5")]
    script.write_text(
        "import multiprocessing, pmdcid.report.parallel as par\n"
        "from pmdcid.io import read_log\nfrom pmdcid.model import load_model\n"
        "from pmdcid.report import make_report\n"
        "print('script ran', flush=True)\n"
        f"logs = [read_log(f) for f in {files!r}]\n"
        f"model = load_model({str(ROOT / 'fixtures' / 'hidden' / 'truth.json')!r})\n"
        "assert par.spare_workers(2 * len(logs) + 2) == 1\n"
        f"make_report(logs, model, {str(tmp_path / 'out')!r})\n"
        "assert multiprocessing.active_children() == []\n")
    env = {**os.environ, "PMDCID_THREADS": "2"}
    res = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                         env=env, cwd=tmp_path, timeout=300)
    assert res.returncode == 0, res.stderr
    assert res.stdout.count("script ran") == 1
    assert res.stderr == ""
    assert len(list((tmp_path / "out").glob("*.png"))) == 8
