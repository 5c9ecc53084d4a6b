"""Round three, family 1 (issue 29): user text reaching generated code, figures or the terminal
is escaped for that language (pmdcid/io/escape.py) or refused; numbers are finite or refused."""

from __future__ import annotations

import ast
import importlib.util
import json
import math
import shutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main

FIX = FIXTURES
#: names a careful attacker or a tired user gives a model file
HOSTILE = [
    'm"""+open("PWNED_py","w").name+""".json',
    "m'''+open('PWNED_py','w').name+'''.json",
    "C:\\Users\\me\\motor.json",
    "a\nsystem('touch PWNED_m')\n.json",
    "a\r%{\nsystem(1)\n%}\n.json",
    "x ??/\nint pwned; \\\n.json",
    "\x1b]0;owned\x07\x1b[2J.json",
    "trailing backslash \\",
    "\u202egnp.json",
]


def _export(tmp_path, name, fmt, out):
    model = tmp_path / name
    shutil.copy(FIX / "paper" / "truth.json", model)
    return CliRunner().invoke(main, ["export", "-m", name, "--to", fmt, "-o", out],
                              catch_exceptions=False)


def _import(path: Path):
    spec = importlib.util.spec_from_file_location("exported_motor", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", HOSTILE[:4] + HOSTILE[6:8], ids=range(6))
def test_python_export_never_runs_the_model_name(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _export(tmp_path, name, "python-control", "motor.py")
    assert res.exit_code == 0, res.output
    ast.parse((tmp_path / "motor.py").read_text())  # a Windows path made a SyntaxError
    mod = _import(tmp_path / "motor.py")
    assert not list(tmp_path.glob("PWNED*"))
    assert name in mod.__doc__  # the docstring reads back the user's name itself


@pytest.mark.parametrize("name", [HOSTILE[3], HOSTILE[4], HOSTILE[6]], ids=range(3))
def test_matlab_export_keeps_a_name_in_its_comment(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _export(tmp_path, name, "matlab", "motor.m")
    assert res.exit_code == 0, res.output
    for f in ("motor.m", "run_motor.m"):
        text = (tmp_path / f).read_text()
        assert "\r" not in text and "\x1b" not in text
        live = [ln for ln in text.splitlines() if "system" in ln and not ln.startswith("%")]
        assert not live, live


def test_c_header_name_with_a_quote_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    res = _export(tmp_path, "truth.json", "c", 'q"x.c')
    assert res.exit_code == 1
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and "#include" in lines[0], res.stderr
    assert not (tmp_path / 'q"x.c').exists() and not (tmp_path / 'q"x.h').exists()


def test_numbers_in_generated_code_are_finite_or_refused():
    from pmdcid.errors import PmdcidError
    from pmdcid.export import number

    assert number(math.inf, "INFINITY") == "INFINITY"
    assert float(number(0.1 + 0.2, "inf")) == 0.1 + 0.2
    with pytest.raises(PmdcidError, match="NaN"):
        number(math.nan, "math.inf")


def test_exported_make_system_needs_a_sample_period(tmp_path, monkeypatch):
    pytest.importorskip("control")
    monkeypatch.chdir(tmp_path)
    assert _export(tmp_path, "truth.json", "python-control", "motor.py").exit_code == 0
    mod = _import(tmp_path / "motor.py")
    for dt in (0, 0.0, -1e-3, math.nan, math.inf):
        with pytest.raises(ValueError, match="dt"):
            mod.make_system(dt)
    with pytest.raises(TypeError, match="dt"):
        mod.make_system("1e-3")
    with pytest.raises(ValueError, match="nope"):
        mod.make_system(1e-3, params={"nope": 1.0})
    assert mod.make_system(1e-3).dt == 1e-3


@pytest.mark.parametrize("text", HOSTILE + ["", "é ü ∑", "\x00\x7f\x85\u2028\udcff", "$\\$"])
def test_escape_rules_read_back(text):
    from pmdcid.io import escape

    assert ast.literal_eval(escape.py_str(text)) == text
    assert ast.literal_eval('"""' + escape.py_text(text) + '"""') == text
    assert escape.py_str(text).isascii() and escape.c_str(text).isascii()
    for s in (escape.terminal(text), escape.m_comment(text), escape.mpl_text(text),
              escape.c_comment(text), escape.xml_text(text)):
        assert s.isprintable(), repr(s)
    assert "*/" not in escape.c_comment(text)
    assert "<" not in escape.xml_text(text) and '"' not in escape.xml_text(text)
    assert escape.m_str(text).count("'") % 2 == 0


def test_terminal_never_gets_an_escape_sequence(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    shutil.copy(FIX / "paper" / "truth.json", tmp_path / "m.json")
    name = "log\x1b]0;owned\x07\x1b[2J.csv"
    res = CliRunner().invoke(main, ["simulate", name, "-m", "m.json", "-o", "o.csv"],
                             catch_exceptions=False)
    assert res.exit_code == 1
    assert "\x1b" not in res.stderr and "\x07" not in res.stderr
    assert "\\x1b]0;owned" in res.stderr  # shown, not acted on


def test_report_with_tex_in_a_log_name_and_a_dot_in_a_parameter(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    model = json.loads((FIX / "paper" / "truth.json").read_text())
    model["parameters"]["my.param"] = {"value": 1.0}
    (tmp_path / "m.json").write_text(json.dumps(model))
    log = "st$\\frac{a$x.csv"
    shutil.copy(FIX / "paper" / "step_1.5V.csv", tmp_path / log)
    res = CliRunner().invoke(main, ["report", log, "-m", "m.json", "-o", "rep"],
                             catch_exceptions=False)
    assert res.exit_code == 0, res.stderr
    assert "my.param" in (tmp_path / "rep" / "report.html").read_text()

