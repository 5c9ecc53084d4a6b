"""A large log read in chunks of rows (pmdcid.io.chunked) gives bit for bit what the whole-file
read gives, and steps aside (the whole-file read serves, with its messages) wherever the two
could differ. The size threshold is lowered so that small files take the chunked path."""

from __future__ import annotations

import numpy as np
import pytest
from ident_util import extreme_numbers
from read_util import CASES, FIXTURE_CSVS, assert_same, read_or_message

import pmdcid.io.chunked as chunked
import pmdcid.io.plain as plain
from pmdcid.io.csvsource import open_source
from pmdcid.io.logs import _split_comments


def _whole_and_chunked(path, monkeypatch, chunk_rows=7):
    """(read by pandas whole, read in chunks of ``chunk_rows`` rows); numpy's path off."""
    monkeypatch.setattr(plain, "MAX_BYTES", -1)
    whole = read_or_message(path)
    monkeypatch.setattr(chunked, "CHUNKED_BYTES", -1)
    monkeypatch.setattr(chunked, "CHUNK_ROWS", chunk_rows)
    return whole, read_or_message(path)


def _takes_chunked_path(path) -> bool:
    src = open_source(str(path))
    return chunked.read_chunked(src, _split_comments(src.head, str(path))[1], 7) is not None


@pytest.mark.parametrize("path", FIXTURE_CSVS[:6], ids=lambda p: f"{p.parent.name}/{p.name}")
def test_fixture_logs_read_the_same_in_chunks(path, monkeypatch):
    assert _takes_chunked_path(path)
    assert_same(*_whole_and_chunked(path, monkeypatch, chunk_rows=1000))


#: the cases where the chunked read steps aside (the numpy path's list differs: pandas parses
#: spaces after commas, nan and empty cells, quotes and byte-order marks the same in chunks)
STEPS_ASIDE = {"integer column with -0", "big integers", "extra text column", "header only"}


@pytest.mark.parametrize("name", CASES)
def test_chunked_read_only_where_it_agrees(name, tmp_path, monkeypatch):
    text, _ = CASES[name]
    path = tmp_path / "log.csv"
    path.write_bytes(text.encode())
    if name != "semicolons":  # the chunked read is asked only for ',' and '.' logs
        assert _takes_chunked_path(path) == (name not in STEPS_ASIDE)
    assert_same(*_whole_and_chunked(path, monkeypatch, chunk_rows=2))


def test_random_numbers_in_chunks_and_more_rows_than_the_head_shows(tmp_path, monkeypatch):
    rng = np.random.default_rng(1616)
    n = 5000
    x = extreme_numbers(rng, n)
    rows = [f"{k * 0.001:.9g},{k % 9 - 4.5},{a:.17g},{b:.6e},{c:.25g}"
            for k, (a, b, c) in enumerate(x)]
    short = [f"{(k + n) * 0.001:.9g},1,2,-0.5,3" for k in range(40000)]  # after the head
    path = tmp_path / "log.csv"
    path.write_text("# kind: random\nt,v,a,b,c\n" + "\n".join(rows + short) + "\n")
    src = open_source(str(path))
    assert chunked._rows_estimate(src, 1) < 45000  # the columns must grow while reading
    assert _takes_chunked_path(path)
    whole, ours = _whole_and_chunked(path, monkeypatch, chunk_rows=333)
    assert not isinstance(whole, str), whole
    assert ours.n == 45000
    assert_same(whole, ours)
