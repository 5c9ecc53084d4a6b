"""pmdcid/identify/jit_cache.py: numba's cache of the kernel filled once, at install."""

import subprocess
import sys

import pytest
from repo_paths import REPO

from pmdcid.identify.jit_cache import CALLED


@pytest.mark.slow
def test_filling_the_cache_compiles_or_loads_every_jitted_function():
    """In a fresh process, fill() leaves each function numba serves from Python with a compiled
    signature (read from the dispatchers: loaded from numba's cache where it holds one,
    compiled into it otherwise); one it does not call would be missing and exit 1."""
    out = subprocess.run([sys.executable, "-m", "pmdcid.identify.jit_cache"], cwd=REPO,
                         capture_output=True, text=True, check=True).stdout
    assert out.strip().split(": ", 2)[-1].split(", ") == [name for _, name in CALLED]
