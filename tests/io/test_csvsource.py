"""pmdcid/io/csvsource.py: opening a log as rigs and spreadsheets export it."""

import bz2
import gzip
import warnings

import numpy as np
import pytest

from pmdcid.errors import LogError
from pmdcid.io import parse_mapping, read_log


def _euro(rows: int, cell: dict[int, str] | None = None) -> str:
    """A European export (';' separated, decimal comma); ``cell``: data row (1-based) -> the
    text of its omega cell."""
    lines = ["t;v;omega"]
    for k in range(rows):
        omega = (cell or {}).get(k + 1, f"{0.5 * np.sin(k / 7):.6f}".replace(".", ","))
        lines.append(f"{k / 1000:.3f};1;{omega}".replace("0.", "0,"))
    return "\n".join(lines) + "\n"


def test_a_thousands_separator_is_named_with_its_cell_and_row(tmp_path):
    p = tmp_path / "euro.csv"
    p.write_text(_euro(40, {30: "1.234,5"}))
    with pytest.raises(LogError, match=r"column 'omega' holds non-numeric value '1\.234,5' \(data "
                                       r"row 30\): a thousands separator \('\.'\) in a number "
                                       r"with ',' decimals"):
        read_log(p)
    p.write_text(_euro(40, {12: "ERR"}))  # any other text: named, in the file's decimal mark
    with pytest.raises(LogError, match=r"'ERR' \(data row 12\): numbers only, with ',' decimals"):
        read_log(p)
    p.write_text(_euro(40))
    assert read_log(p)["omega"][7] == pytest.approx(0.5 * np.sin(1.0), abs=1e-6)


def test_a_grouped_number_with_decimal_points_is_named_too(tmp_path):
    p = tmp_path / "us.csv"
    rows = [f"{k / 1000:.3f};1;{'1,234.5' if k == 20 else f'{k / 10:.1f}'}" for k in range(40)]
    p.write_text("t;v;omega\n" + "\n".join(rows) + "\n")
    with pytest.raises(LogError, match=r"'1,234\.5' \(data row 21\): a thousands separator "
                                       r"\(','\) in a number with '\.' decimals"):
        read_log(p)


def test_a_first_line_that_is_no_header_is_named_with_the_fix(tmp_path):
    rows = "".join(f"{k / 1000:.3f},1,{k / 10:.1f}\n" for k in range(40))
    p = tmp_path / "rig.csv"
    p.write_text("# kind: step\nLogged by rig 3 on 2024-01-01\nt,v,omega\n" + rows)
    with pytest.raises(LogError, match=r"line 2 \('Logged by rig 3 on 2024-01-01'\) is no header "
                                       r"\(1 field\(s\), the rows 3\); line 3 \('t,v,omega'\) "
                                       r"is: start the lines above it with '#' or delete them$"):
        read_log(p)
    p.write_text("# kind: step\n# Logged by rig 3 on 2024-01-01\nt,v,omega\n" + rows)
    assert read_log(p).n == 40


def test_canonical_names_match_in_any_case_where_unambiguous(tmp_path):
    rows = "".join(f"{k / 1000:.3f},1,{k / 10:.1f},{k / 5:.1f}\n" for k in range(40))
    p = tmp_path / "upper.csv"
    p.write_text("T,V,OMEGA,Omega\n" + rows)  # two speed columns: neither is taken
    log = read_log(p)
    assert log.dt == pytest.approx(1e-3) and log.drive == "v" and not log.has("omega")
    p.write_text("T,V,OMEGA,w\n" + rows)
    assert read_log(p)["omega"][10] == pytest.approx(1.0)
    log = read_log(p, parse_mapping(["omega=w"]))  # a mapping wins over the case rule
    assert log["omega"][10] == pytest.approx(2.0)


def test_a_column_named_t_in_another_case_never_displaces_the_time(tmp_path):
    """A temperature (or torque) column 'T' beside the time: a header naming the time's unit
    is read as t, and beside a bare 'time' column 'T' is not taken for t (the user maps it)."""
    rows = "".join(f"{k / 1000:.3f},1,{k / 10:.1f},25.0\n" for k in range(40))
    p = tmp_path / "temp.csv"
    p.write_text("Time (s),v,omega,T\n" + rows)
    assert read_log(p).dt == pytest.approx(1e-3)
    p.write_text("time,v,omega,T\n" + rows)
    with pytest.raises(LogError, match="has no time column 't'.*-c t=SOURCE"):
        read_log(p)
    assert read_log(p, parse_mapping(["t=time"])).dt == pytest.approx(1e-3)


def test_a_whitespace_separated_log_is_read(tmp_path):
    rows = "".join(f"{k / 1000:.3f}  1\t{k / 10:.1f}\n" for k in range(40))
    p = tmp_path / "spaces.csv"
    p.write_text("t v  omega\n" + rows)
    log = read_log(p)
    assert log.dt == pytest.approx(1e-3) and log["omega"][10] == pytest.approx(1.0)
    p.write_text("t v omega\n" + rows.replace("0.005  1", "0.005 1 7"))  # a ragged row
    with pytest.raises(LogError, match=r"looks space-separated \(header 't v omega'\) but its "
                                       r"rows do not have as many separators"):
        read_log(p)


def test_iso_8601_date_times_are_read_as_seconds_from_the_first(tmp_path):
    start = np.datetime64("2024-03-01T23:59:59.990")  # across midnight
    stamps = start + np.arange(40) * np.timedelta64(1, "ms")
    rows = "".join(f"{str(s).replace('T', ' ')},1,{k / 10:.1f}\n" for k, s in enumerate(stamps))
    p = tmp_path / "wall.csv"
    p.write_text("timestamp,v,omega\n" + rows)
    with pytest.warns(UserWarning, match=r"column 'timestamp' holds date-times \(the first "
                                         r"'2024-03-01 23:59:59\.990'\): read as t, in seconds"):
        log = read_log(p)
    assert log.dt == pytest.approx(1e-3) and log.t_file[-1] == pytest.approx(0.039)
    p.write_text("t,v,omega\n" + rows.replace(" ", "T").replace(",1,", "Z,1,"))  # 'T', UTC 'Z'
    with pytest.warns(UserWarning, match="column 't' holds date-times"):
        assert read_log(p).n == 40


def test_a_compressed_log_is_named_as_such_with_the_way_out(tmp_path):
    p = tmp_path / "run.csv"
    p.write_bytes(gzip.compress(b"t,v\n0,1\n0.001,1\n0.002,1\n"))
    with pytest.raises(LogError, match=r"is gzip-compressed \(its first bytes are 1f 8b\), not "
                                       r"CSV text: decompress it first \(zcat FILE > log\.csv\)"):
        read_log(p)
    p.write_bytes(bz2.compress(b"t,v\n0,1\n0.001,1\n0.002,1\n"))
    with pytest.raises(LogError, match=r"is bzip2-compressed"):
        read_log(p)


def test_nul_padding_after_the_last_row_is_ignored(tmp_path):
    rows = "".join(f"{k / 1000:.3f},1,{k / 10:.1f}\n" for k in range(40))
    p = tmp_path / "padded.csv"
    p.write_bytes(("t,v,omega\n" + rows).encode() + b"\x00" * 500)
    with pytest.warns(UserWarning, match=r"ignored 500 NUL byte\(s\) after the last row"):
        log = read_log(p)
    assert log.n == 40 and log["omega"][-1] == pytest.approx(3.9)
    big = "".join(f"{k / 1000:.3f},1,{k / 10:.1f}\n" for k in range(6000))  # past the head
    p.write_bytes(("t,v,omega\n" + big).encode() + b"\x00" * 30 + b"\n" + big[:40].encode())
    with pytest.raises(LogError) as got:  # NULs inside the log: refused, counted, not printed
        read_log(p)
    assert "with 30 NUL byte(s)" in str(got.value) and "\\x00" not in str(got.value)


@pytest.mark.parametrize("sep", [",", ";"])  # the plain reader and pandas
def test_a_file_cut_inside_its_last_row_drops_that_row_and_says_so(tmp_path, sep):
    """A logger stopped mid-write leaves a last row without a line end, perhaps cut inside a
    number (2.03712649 -> 2.03712): that row is not used, with one warning saying how to use
    it; a file that ends in a line end, blanks or a logger's NUL padding keeps every row."""
    from pmdcid.errors import PmdcidWarning

    rows = [f"{k / 1000:.3f}{sep}1{sep}{2.03712649 + k}" for k in range(50)]
    whole = "t" + sep + "v" + sep + "omega\n" + "\n".join(rows)
    p = tmp_path / "log.csv"
    p.write_text(whole[:-3])
    with pytest.warns(PmdcidWarning, match="last row has no line end after it.*end the file "
                                           "with a newline"):
        log = read_log(p)
    assert len(log.t) == 49 and log.data["omega"][-1] == pytest.approx(2.03712649 + 48)
    for ending in ("\n", "\r\n", "\n\n  ", "\n\x00\x00"):
        p.write_bytes((whole + ending).encode())
        with warnings.catch_warnings(record=True) as seen:
            warnings.simplefilter("always")
            assert len(read_log(p).t) == 50
        assert not [w for w in seen if "no line end" in str(w.message)], ending


def test_a_log_with_both_v_and_tau_has_one_input_and_says_which(tmp_path, rng):
    """Fuzzing: ``-c tau=COLUMN`` on a log that also holds a ``v`` column fitted the voltage
    and never said the torque went unused. The mapped one is the input; unmapped, ``v`` as
    before; both mapped is refused; every case says so in one line."""
    from pmdcid.errors import PmdcidWarning

    n = 200
    t = np.arange(n) * 1e-3
    cols = {"t": t, "v": np.full(n, 6.0), "cur": np.full(n, 0.5), "tau": np.full(n, 0.01),
            "omega": rng.normal(10.0, 0.1, n)}
    f = tmp_path / "both.csv"
    np.savetxt(f, np.column_stack(list(cols.values())), delimiter=",",
               header=",".join(cols), comments="")
    with pytest.warns(PmdcidWarning, match=r"both 'v' and 'tau': 'tau' is the input \(mapped\)"
                                           r", 'v' \(column 'v'\) is not used"):
        log = read_log(f, parse_mapping(["tau=cur*0.02"], None))
    assert log.drive == "tau" and np.allclose(log.u, 0.01) and "v" not in log.data
    with pytest.warns(PmdcidWarning, match=r"'v' is the input \(the voltage, as a log with "
                                           r"both is read\), 'tau' \(column 'tau'\) is not used"):
        log = read_log(f)
    assert log.drive == "v" and "tau" not in log.data
    with pytest.raises(LogError, match="both 'v' and 'tau' are mapped"):
        read_log(f, parse_mapping(["tau=cur*0.02", "v=v*1"], None))


@pytest.mark.parametrize("encoding", ["latin-1", "cp1252"])
def test_a_latin_1_header_is_read_as_such_and_said(tmp_path, encoding):
    """A rig writing Windows-1252 / Latin-1 (``time [µs]``, ``speed [°/s]``, one byte each):
    before, decoded as UTF-8 with replacement characters, the header's units were lost
    (``time [�s]``) and every command refused the log with ``has no time column 't' (columns
    are time [�s], ...)``, never naming the encoding. Now read as Windows-1252, one warning
    saying so; the same file in UTF-8 reads as before, without it."""
    from click.testing import CliRunner

    from pmdcid.cli import main

    rng = np.random.default_rng(31)
    n = 1000
    t = np.arange(n) * 1e-3
    v = np.where(t >= 0.1, 6.0, 0.0)
    w = np.where(t >= 0.1, 20.0 * (1 - np.exp(-np.clip(t - 0.1, 0, None) / 0.1)), 0.0)
    w = w + rng.normal(0, 0.02, n)
    text = "time [µs];voltage [V];speed [°/s]\n" + "".join(
        f"{a * 1e6:.1f};{b:.4f};{np.degrees(c):.5f}\n".replace(".", ",")
        for a, b, c in zip(t, v, w, strict=True))
    p = tmp_path / "rig.csv"
    p.write_bytes(text.encode(encoding))
    res = CliRunner().invoke(main, ["channels", str(p)])
    assert res.exit_code == 0 and "time [µs]" in res.stdout and "°/s" in res.stdout, res.output
    model = tmp_path / "m.json"
    res = CliRunner().invoke(main, ["fit-mechanical", str(p), "-m", str(model)])
    assert res.exit_code == 0, res.stderr
    said = [ln for ln in res.stderr.splitlines() if "UTF-8" in ln]
    assert said == [f"warning: {p}: is not UTF-8 text (byte 0xb5 in line 1): read as "
                    "Windows-1252 (Latin-1), which makes line 1 'time [µs];voltage [V];speed "
                    "[°/s]'; save the log as UTF-8 to read it without this warning"], res.stderr
    res = CliRunner().invoke(main, ["plan", "--check", str(p), "-m", str(model), "-o",
                                    str(tmp_path / "plan")])
    assert res.exit_code == 0, res.stderr
    p.write_bytes(text.encode("utf-8"))
    res = CliRunner().invoke(main, ["fit-mechanical", str(p), "-m", str(tmp_path / "u.json")])
    assert res.exit_code == 0 and "UTF-8" not in res.stderr, res.stderr
    log = read_log(p)
    p.write_bytes(text.encode(encoding))
    with pytest.warns(UserWarning, match="is not UTF-8 text"):
        same = read_log(p)
    np.testing.assert_array_equal(same["omega"], log["omega"])
    np.testing.assert_array_equal(same.t, log.t)
