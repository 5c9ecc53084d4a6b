"""Reading plain-number logs with numpy gives bit for bit what pandas gives, and steps aside
(pandas reads the file) wherever the two could differ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from ident_util import extreme_numbers
from read_util import CASES, FIXTURE_CSVS, assert_same, read_or_message
from repo_paths import REPO

import pmdcid.io.plain as plain
from pmdcid.io.logs import _split_comments

ROOT = REPO
SHARED = ROOT.parent / "shared" / "data"


def _both(path, monkeypatch):
    """(read with the numpy path allowed, read by pandas only)."""
    fast = read_or_message(path)
    monkeypatch.setattr(plain, "MAX_BYTES", -1)
    slow = read_or_message(path)
    monkeypatch.setattr(plain, "MAX_BYTES", 16 << 20)
    return fast, slow


def _takes_numpy_path(path) -> bool:
    text = Path(path).read_bytes()[:65536].decode("utf-8", errors="replace")
    return plain.read_plain(str(path), _split_comments(text, str(path))[1]) is not None


@pytest.mark.parametrize("path", FIXTURE_CSVS, ids=lambda p: f"{p.parent.name}/{p.name}")
def test_fixture_logs_read_the_same_by_numpy_and_pandas(path, monkeypatch):
    assert _takes_numpy_path(path)
    assert_same(*_both(path, monkeypatch))


def test_shared_logs_read_the_same_by_numpy_and_pandas(monkeypatch):
    paths = sorted(SHARED.rglob("*.csv")) if SHARED.is_dir() else []
    if not paths:
        pytest.skip(f"no shared data logs in {SHARED}")
    for path in paths:
        assert_same(*_both(path, monkeypatch))




@pytest.mark.parametrize("name", CASES)
def test_numpy_path_only_where_it_agrees(name, tmp_path, monkeypatch):
    text, numpy_expected = CASES[name]
    path = tmp_path / "log.csv"
    path.write_bytes(text.encode())
    assert _takes_numpy_path(path) == numpy_expected
    assert_same(*_both(path, monkeypatch))


def test_random_numbers_in_many_formats_agree(tmp_path, monkeypatch):
    rng = np.random.default_rng(16)
    n = 3000
    x = extreme_numbers(rng, n)
    rows = [f"{k * 0.001:.9g},{a:.17g},{b:.6e},{c:.12f},{a:.25g},{b:.3g}"
            for k, (a, b, c) in enumerate(x)]
    path = tmp_path / "log.csv"
    path.write_text("# kind: random\nt,v,a,b,c,d\n" + "\n".join(rows) + "\n")
    assert _takes_numpy_path(path)
    assert_same(*_both(path, monkeypatch))


def test_a_simulation_needs_no_pandas(tmp_path):
    import subprocess
    import sys

    code = ("import sys; from pmdcid.io import read_log; "
            f"read_log({str(FIXTURE_CSVS[0])!r}); print('pandas' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
