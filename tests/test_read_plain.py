"""Reading plain-number logs with numpy gives bit for bit what pandas gives, and steps aside
(pandas reads the file) wherever the two could differ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ident_util import extreme_numbers

import pmdcid.io.plain as plain
from pmdcid.errors import PmdcidError
from pmdcid.io import read_log
from pmdcid.io.logs import _split_comments

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
FIXTURES = sorted((ROOT / "fixtures").glob("*/*.csv"))


def _read(path):
    try:
        return read_log(path, defer=True)
    except PmdcidError as exc:  # a log both readers refuse: the same message
        return str(exc)


def _both(path, monkeypatch):
    """(read with the numpy path allowed, read by pandas only)."""
    fast = _read(path)
    monkeypatch.setattr(plain, "MAX_BYTES", -1)
    slow = _read(path)
    monkeypatch.setattr(plain, "MAX_BYTES", 16 << 20)
    return fast, slow


def _takes_numpy_path(path) -> bool:
    text = Path(path).read_bytes()[:65536].decode("utf-8", errors="replace")
    return plain.read_plain(str(path), _split_comments(text, str(path))[1]) is not None


def _same(a, b) -> None:
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


@pytest.mark.parametrize("path", FIXTURES, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_fixture_logs_read_the_same_by_numpy_and_pandas(path, monkeypatch):
    assert _takes_numpy_path(path)
    _same(*_both(path, monkeypatch))


def test_shared_logs_read_the_same_by_numpy_and_pandas(monkeypatch):
    paths = sorted(SHARED.rglob("*.csv")) if SHARED.is_dir() else []
    if not paths:
        pytest.skip(f"no shared data logs in {SHARED}")
    for path in paths:
        _same(*_both(path, monkeypatch))


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


@pytest.mark.parametrize("name", CASES)
def test_numpy_path_only_where_it_agrees(name, tmp_path, monkeypatch):
    text, numpy_expected = CASES[name]
    path = tmp_path / "log.csv"
    path.write_bytes(text.encode())
    assert _takes_numpy_path(path) == numpy_expected
    _same(*_both(path, monkeypatch))


def test_random_numbers_in_many_formats_agree(tmp_path, monkeypatch):
    rng = np.random.default_rng(16)
    n = 3000
    x = extreme_numbers(rng, n)
    rows = [f"{k * 0.001:.9g},{a:.17g},{b:.6e},{c:.12f},{a:.25g},{b:.3g}"
            for k, (a, b, c) in enumerate(x)]
    path = tmp_path / "log.csv"
    path.write_text("# kind: random\nt,v,a,b,c,d\n" + "\n".join(rows) + "\n")
    assert _takes_numpy_path(path)
    _same(*_both(path, monkeypatch))


def test_a_simulation_needs_no_pandas(tmp_path):
    import subprocess
    import sys

    code = ("import sys; from pmdcid.io import read_log; "
            f"read_log({str(FIXTURES[0])!r}); print('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
