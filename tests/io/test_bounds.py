"""Round three, family 4 (issue 29): resource bounds checked before the work, in one line naming
the file: a line of a log, a mapping expression's length and nesting, diagnose's rows."""

from __future__ import annotations

import io

import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.errors import LogError

FIX = FIXTURES


def _one_error(res, *patterns: str) -> str:
    lines = res.stderr.strip().splitlines()
    assert res.exit_code == 1 and len(lines) == 1, res.stderr
    for pat in patterns:
        assert pat in lines[0], lines[0]
    return lines[0]


@pytest.mark.parametrize("shape", ["one-row-of-fields", "one-huge-cell", "middle"])
def test_a_huge_line_fails_at_once_naming_the_file(paper_step, shape):
    """A 50 MB single line took 62 s and 5.5 GB, then an error naming no file."""
    from pmdcid.io import bounds

    n = bounds.MAX_LINE_BYTES + 1000
    with open(paper_step / "big.csv", "w") as fh:
        if shape == "one-row-of-fields":
            fh.write("1," * (n // 2) + "\n")
        elif shape == "one-huge-cell":
            fh.write("t,v\n0," + "1" * n + "\n")
        else:
            fh.write("t,v\n" + "".join(f"{k * 1e-3:.3f},1.5\n" for k in range(100)))
            fh.write("0.1," + "2" * n + "\n")
    res = CliRunner().invoke(main, ["simulate", "big.csv", "-m", "m.json", "-o", "o.csv"],
                             catch_exceptions=False)
    line = _one_error(res, "big.csv: line ", "longer than")
    assert ("line 102 " in line) == (shape == "middle"), line


def test_the_line_scan_counts_lines_and_accepts_long_logs(monkeypatch):
    from pmdcid.io import bounds

    monkeypatch.setattr(bounds, "MAX_LINE_BYTES", 10)
    monkeypatch.setattr(bounds, "SCAN_CHUNK", 7)  # lines across chunk borders
    ok = b"t,v\r\n" + b"0.001,1.5\r\n" * 50
    assert bounds.check_lines(io.BytesIO(ok), "x.csv") is None
    with pytest.raises(LogError, match="x.csv: line 4 is longer"):
        bounds.check_lines(io.BytesIO(b"t,v\n1,2\n3,4\n5,123456789012\n"), "x.csv")
    with pytest.raises(LogError, match="x.csv: line 1 is longer"):
        bounds.check_lines(io.BytesIO(b"x" * 100), "x.csv")


@pytest.mark.parametrize("expr", [
    "v=" + "(" * 400 + "v" + ")" * 400,
    "v=" + "-(" * 40 + "v" + ")" * 40,
    "v=" + "+".join(["(v)"] * 3000),
], ids=["deep", "signs", "long"])
def test_mapping_expressions_are_bounded(paper_step, expr, tmp_path):
    """Deep or long expressions raised RecursionError ('internal error')."""
    res = CliRunner().invoke(main, ["simulate", "step.csv", "-m", "m.json", "-o", "o.csv",
                                    "-c", expr], catch_exceptions=False)
    assert res.exit_code == 2 and "RecursionError" not in res.output, res.output
    assert "nested deeper" in res.output or "characters long" in res.output
    (tmp_path / "map.txt").write_text(expr + "\n")
    res = CliRunner().invoke(main, ["simulate", "step.csv", "-m", "m.json", "-o", "o.csv",
                                    "--map", "map.txt"], catch_exceptions=False)
    _one_error(res, "map.txt: column mapping")


def test_diagnose_refuses_more_rows_than_it_can_take(paper_step, monkeypatch):
    """5 million rows: 6.5 min and 4.5 GB; past the bound diagnose says how to proceed."""
    from pmdcid.io import bounds

    monkeypatch.setattr(bounds, "MAX_DIAGNOSE_ROWS", 2000)
    res = CliRunner().invoke(main, ["diagnose", "step.csv", "-m", "m.json", "-o", "new.json"],
                             catch_exceptions=False)
    _one_error(res, "step.csv: diagnose takes at most 2,000 rows", "keep one row in 2")
    assert not (paper_step / "new.json").exists()


def test_out_of_memory_names_the_file(paper_step, monkeypatch):
    """'out of memory: the log is too large' named no file."""
    from pmdcid.io import bounds

    def exhausted(*a, **k):
        raise MemoryError

    monkeypatch.setattr(bounds, "check_lines", exhausted)
    res = CliRunner().invoke(main, ["simulate", "step.csv", "-m", "m.json", "-o", "o.csv"],
                             catch_exceptions=False)
    _one_error(res, "error: step.csv: out of memory")
