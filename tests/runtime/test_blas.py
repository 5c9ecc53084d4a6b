"""The command line pins OpenBLAS's kernels before numpy loads (runtime/blas.py)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from pmdcid.runtime import blas

PROBE = ("import os; from pmdcid.runtime.blas import pin_blas_kernels; "
         "print(pin_blas_kernels(), os.environ.get('OPENBLAS_CORETYPE'))")


def _probe(**env) -> str:
    clean = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_CORETYPE", "PMDCID_BLAS")}
    out = subprocess.run([sys.executable, "-c", PROBE], env={**clean, **env},
                         capture_output=True, text=True, check=True)
    return out.stdout.strip()


@pytest.mark.skipif(not blas.NEEDS <= blas._cpu_flags(), reason="no AVX2/FMA on this CPU")
def test_a_fresh_process_gets_the_pinned_kernels():
    assert _probe() == "True Haswell"
    # the kernels OpenBLAS then loads (a command's own process)
    code = ("import sys; from pmdcid.cli import main; sys.argv = ['pmdcid', 'channels', "
            f"{str(blas.__file__)!r}]\ntry:\n    main()\nexcept SystemExit:\n    pass\n"
            "from threadpoolctl import threadpool_info\n"
            "print(sorted({i.get('architecture') for i in threadpool_info()}))")
    pytest.importorskip("threadpoolctl")
    clean = {k: v for k, v in os.environ.items() if k != "OPENBLAS_CORETYPE"}
    got = subprocess.run([sys.executable, "-c", code], env=clean, capture_output=True,
                         text=True)
    assert got.stdout.strip().splitlines()[-1] == "['Haswell']", got.stdout + got.stderr


def test_the_users_choice_is_kept():
    assert _probe(PMDCID_BLAS="default") == "False None"
    assert _probe(OPENBLAS_CORETYPE="Zen") == "False Zen"


def test_nothing_is_done_once_numpy_is_loaded(monkeypatch):
    import numpy  # noqa: F401  (loaded: too late to choose)

    monkeypatch.delenv("OPENBLAS_CORETYPE", raising=False)
    monkeypatch.delenv("PMDCID_BLAS", raising=False)
    assert blas.pin_blas_kernels() is False
    assert "OPENBLAS_CORETYPE" not in os.environ
