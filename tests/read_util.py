"""Shared helpers of the reader tests (tests/io/test_plain.py, test_chunked.py, the odd files of
tests/io/formats/): the logs and text cases read by more than one path, the bit-for-bit
comparison of two reads, a motor step log to write in each format, and the CLI run on it."""

from __future__ import annotations

import numpy as np
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.errors import PmdcidError
from pmdcid.io import read_log

#: samples of :func:`step_motor`'s log
STEP_N = 400


def step_motor(seed: int, n: int = STEP_N):
    """(t [s], v [V], omega [rad/s]) of a 0 -> 6 V step at 0.1 s into a first-order motor
    (20 rad/s, 0.1 s), 1 kHz, speed noise 0.02 rad/s from ``seed``."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 1e-3
    v = np.where(t >= 0.1, 6.0, 0.0)
    w = np.where(t >= 0.1, 20.0 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.1)), 0.0)
    return t, v, w + rng.normal(0, 0.02, n)


def run_cli(args) -> tuple[int, str, list[str]]:
    """(exit code, stdout, stderr lines) of ``pmdcid ARGS`` run in process."""
    res = CliRunner().invoke(main, [str(a) for a in args])
    return res.exit_code, res.stdout, res.stderr.strip().splitlines()


#: every CSV log of the repository's fixtures
FIXTURE_CSVS = sorted(FIXTURES.glob("*/*.csv"))

CASES = {
    # name: (text, numpy path expected)
    "plain": ("# kind: triangle\nt,v,omega\n0,-0,1.5\n0.001,2e-3,-0\n0.002,.5,3.\n", True),
    "comments and blank lines": ("# a: 1\n\n# b: 2\nt,v\n0,1\n\n0.001,2\n0.002,3\n", True),
    "crlf": ("# kind: x\r\nt,v\r\n0,1.25\r\n0.001,-2.5\r\n0.002,3\r\n", True),
    "mixed signs and exponents": ("t,v\n0,+1E+2\n0.001,-2.5e-3\n0.002,3E0\n", True),
    "integer column with -0": ("t,v,counts\n0,1.5,-0\n0.001,2.5,4\n0.002,3.5,-7\n", False),
    "big integers": ("t,v,ns\n0,1,9007199254740993\n0.001,2,9007199254740995\n"
                     "0.002,3,9007199254740997\n", False),
    "space after comma": ("t, v\n0, 1\n0.001, 2\n0.002, 3\n", False),
    "nan cell": ("t,v,i\n0,1,nan\n0.001,2,0.5\n0.002,3,0.25\n", False),
    "empty cell": ("t,v,i\n0,1,\n0.001,2,0.5\n0.002,3,0.25\n", False),
    "short row": ("t,v,i\n0,1\n0.001,2,0.5\n0.002,3,0.25\n", False),
    "long row": ("t,v\n0,1,7\n0.001,2,8\n0.002,3,9\n", False),
    "quoted header": ('"t","v"\n0,1\n0.001,2\n0.002,3\n', False),
    "duplicate names": ("t,v,v\n0,1,2\n0.001,2,3\n0.002,3,4\n", True),
    "extra text column": ("t,v,note\n0,1,a\n0.001,2,b\n0.002,3,c\n", False),
    "byte-order mark": ("\ufefft,v\n0,1\n0.001,2\n0.002,3\n", False),
    "semicolons": ("t;v\n0;1,5\n0,001;2,5\n0,002;3\n", False),
    "header only": ("t,v\n", False),
    "overload marker": ("t,v\n0,1.5\n0.001,9.9e37\n0.002,3\n", True),
    "huge value": ("t,v\n0,1\n0.001,1e400\n0.002,3\n", False),
}


def read_or_message(path):
    try:
        return read_log(path, defer=True)
    except PmdcidError as exc:  # a log both readers refuse: the same message
        return str(exc)


def assert_same(a, b) -> None:
    if isinstance(a, str) or isinstance(b, str):
        assert a == b
        return
    assert a.t.tobytes() == b.t.tobytes()
    assert a.dt == b.dt
    assert a.meta == b.meta
    for mine, theirs in ((a.data, b.data), (a.extra, b.extra)):
        assert mine.keys() == theirs.keys()
        for k in mine:
            assert mine[k].tobytes() == theirs[k].tobytes(), k  # bitwise, signs of zero too
