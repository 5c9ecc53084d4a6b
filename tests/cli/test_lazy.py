"""The lazy command group: `pmdcid --help` lists every command without importing any of them,
and every registered name is defined by the module the registry names."""

from __future__ import annotations

import subprocess
import sys

import pytest
from click.testing import CliRunner

from pmdcid.cli import COMMANDS, main, short_help

PROBE = """
import sys
from pmdcid.cli import main
try:
    main(["--help"])
except SystemExit:
    pass
loaded = sorted(m for m in sys.modules if m.startswith("pmdcid.cli.cmd_") or m in
                ("numpy", "scipy", "pandas", "numba", "matplotlib"))
print("LOADED:" + ",".join(loaded))
"""


def test_help_lists_every_command_without_importing_them():
    out = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True,
                         timeout=120, check=True).stdout
    listing, loaded = out.split("LOADED:")
    assert loaded.strip() == ""
    section = listing.split("Commands:", 1)[1]
    for name in COMMANDS:
        assert f"  {name} " in section, name


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_registered_module_defines_the_command_with_that_help(name):
    cmd = main.commands[name]  # imports the module the registry names
    assert cmd.name == name
    help_line = COMMANDS[name][1]
    assert short_help(help_line, 45) == cmd.get_short_help_str(45)


def test_unknown_command_is_a_usage_error():
    res = CliRunner().invoke(main, ["no-such-command"])
    assert res.exit_code == 2
    assert "No such command" in res.output


def test_python_dash_m_pmdcid_is_the_command_line():
    """``python -m pmdcid`` runs the same command line as the ``pmdcid`` script, named so in
    its usage (fuzzing found "No module named pmdcid.__main__")."""
    res = subprocess.run([sys.executable, "-m", "pmdcid", "no-such-command"],
                         capture_output=True, text=True, timeout=120)
    assert res.returncode == 2 and "Usage: pmdcid " in res.stderr, res.stderr
    assert "No such command" in res.stderr
