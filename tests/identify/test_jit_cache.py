"""pmdcid/identify/jit_cache.py: numba's cache of the kernel filled once, at install."""

import json
import subprocess
import sys

import pytest
from repo_paths import REPO

#: every numba function called from Python (module, name); the ones they call (the LuGre loop,
#: the matrix exponential) are compiled, and cached, with them
JITTED = [("simulate.kernel", "_run"), ("simulate.kernel", "_run_into"),
          ("simulate.kernel", "discretize_into"), ("identify.grid", "_batch_cost"),
          ("simulate.terms", "dead_zone"), ("simulate.terms", "static_friction"),
          ("simulate.terms", "friction_curve"), ("simulate.terms", "sliding_friction")]

PROBE = f"""
import importlib, json
from pmdcid.identify.jit_cache import fill
fill()
print(json.dumps({{f"{{m}}.{{n}}": len(getattr(importlib.import_module("pmdcid." + m), n)
                   .signatures) for m, n in {JITTED!r}}}))
"""


@pytest.mark.slow
def test_filling_the_cache_compiles_or_loads_every_jitted_function():
    """Each function has a compiled signature after fill() in a fresh process (loaded from
    numba's cache where it holds one, compiled into it otherwise: numba's cache=True)."""
    out = subprocess.run([sys.executable, "-c", PROBE], cwd=REPO, capture_output=True,
                         text=True, check=True).stdout
    got = json.loads(out.strip().splitlines()[-1])
    assert all(v >= 1 for v in got.values()), got
