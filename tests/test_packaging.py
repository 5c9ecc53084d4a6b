"""pyproject.toml's packaging metadata: the licence as an SPDX expression with its files (PEP
639; the TOML table form is deprecated from setuptools 77), and a build that can read it."""

import re
import sys

import pytest
from repo_paths import REPO

if sys.version_info < (3, 11):
    pytest.skip("tomllib is Python 3.11+", allow_module_level=True)
import tomllib


@pytest.fixture(scope="module")
def pyproject():
    with open(REPO / "pyproject.toml", "rb") as fh:
        return tomllib.load(fh)


def test_licence_is_an_spdx_string_with_its_files(pyproject):
    project = pyproject["project"]
    # pmdcid is MIT; the vendored FMI 2.0 headers it ships are BSD-2-Clause
    assert project["license"] == "MIT AND BSD-2-Clause"
    files = project["license-files"]
    assert files and all((REPO / f).is_file() for f in files)
    assert "MIT License" in (REPO / "LICENSE").read_text()


def test_the_build_requires_a_setuptools_that_reads_it(pyproject):
    req = next(r for r in pyproject["build-system"]["requires"] if r.startswith("setuptools"))
    m = re.fullmatch(r"setuptools>=(\d+)(\.\d+)*", req.replace(" ", ""))
    assert m and int(m.group(1)) >= 77, req
