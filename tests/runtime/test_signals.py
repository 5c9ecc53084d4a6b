"""Round three, family 5 (issue 29): every signal that ends a command is handled as SIGTERM
(rollback, no temporary file, exit 128 + its number), and an interrupt stops the pool's work
promptly instead of letting every remaining piece run first."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from repo_paths import FIXTURES

import pmdcid

FIX = FIXTURES
ROOT = Path(pmdcid.__file__).resolve().parents[1]  # the code under test, for the child

#: a child running one command, which signals itself at a chosen point (deterministic timing)
CHILD = """
import os, signal, sys
import {module} as target
real = target.{name}
def then_signal(*a, **k):
    {before}
    out = real(*a, **k)
    {after}
    return out
target.{name} = then_signal
from pmdcid.cli import main
sys.argv = ["pmdcid", *sys.argv[1:]]
main()
"""
KILL = "os.kill(os.getpid(), signal.{sig})"


def _child(tmp_path, module, name, args, sig, after: bool):
    code = CHILD.format(module=module, name=name, before="" if after else KILL.format(sig=sig),
                        after=KILL.format(sig=sig) if after else "")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PMDCID_THREADS": "2"}
    env.pop("PMDCID_DEBUG", None)
    return subprocess.run([sys.executable, "-c", code, *args], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("stage, log, where, after", [
    ("fit-electrical", "blocked_1.5V.csv", ("pmdcid.files", "save_model"), True),
    ("fit-nonlinear", "triangle.csv", ("pmdcid.fit.solver", "solve"), False),
], ids=["after-the-model-write", "during-the-fit"])
def test_sighup_is_handled_like_sigterm(tmp_path, stage, log, where, after):
    shutil.copy(FIX / "paper" / "truth.json", tmp_path / "model.json")
    shutil.copy(FIX / "paper" / log, tmp_path / "log.csv")
    before = (tmp_path / "model.json").read_bytes()
    proc = _child(tmp_path, *where, [stage, "log.csv", "-m", "model.json"], "SIGHUP", after)
    assert proc.returncode == 128 + signal.SIGHUP, (proc.returncode, proc.stderr)
    assert proc.stderr.strip().splitlines() == ["error: terminated (SIGHUP): nothing was written"]
    assert (tmp_path / "model.json").read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log.csv", "model.json"]


def test_an_interrupt_cancels_the_remaining_pieces(monkeypatch):
    """Ctrl-C in one piece of a map: no thread takes another piece (diagnose's refits took
    16-34 s to stop, the pool finishing its pieces first)."""
    from pmdcid.runtime import cpus

    monkeypatch.setenv("PMDCID_THREADS", "2")
    if cpus.workers() < 2:
        pytest.skip("one CPU: the map is serial")
    ran = []
    lock = threading.Lock()
    started = threading.Event()

    def piece(k):
        with lock:
            ran.append(k)
        if k == 0:
            started.wait(5)  # the other thread is in a piece too
            raise KeyboardInterrupt
        started.set()
        for _ in range(20):
            inner(k)

    def inner(k):  # a helper's nested map (a candidate's Jacobian) stops at once too
        cpus.pmap(lambda x: x, [k, k])
        threading.Event().wait(0.005)

    with pytest.raises(KeyboardInterrupt):
        cpus.pmap(piece, range(40))
    assert len(ran) <= 3, f"{len(ran)} pieces ran after the interrupt"
    assert cpus.pmap(lambda x: 2 * x, range(4)) == [0, 2, 4, 6]  # the next map runs again


def test_nohup_keeps_sighup_ignored(tmp_path):
    """Under nohup (SIGHUP ignored) a closed terminal must not end the command."""
    code = ("import signal, sys; signal.signal(signal.SIGHUP, signal.SIG_IGN)\n"
            "from pmdcid.runtime.signals import install_sigterm\n"
            "install_sigterm()\n"
            "sys.exit(0 if signal.getsignal(signal.SIGHUP) == signal.SIG_IGN else 3)\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    assert subprocess.run([sys.executable, "-c", code], env=env, timeout=60).returncode == 0
