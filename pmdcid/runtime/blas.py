"""OpenBLAS's kernels for a ``pmdcid`` command's own process (and the test suite's): the same
on every x86-64 machine, so that a log gives the same numbers wherever it is identified.

OpenBLAS picks its kernels by the CPU it loads on (AVX-512 on recent Xeons, AVX2 on most
others), and the kernels round differently in the last bits. A simulation-error fit on a rough
cost (the stick-slip and dead-zone events) amplifies those bits into a different stopping point
where two answers are nearly as good: measured in session 21 on an AVX-512 Xeon, three of the
suite's single-seed round trips (tests/diagnose: the thin two-step logs' asymmetry, the
lag-and-latency split at 500 Hz, the dead zone read with the lag) landed elsewhere than with
the AVX2 kernels they were written on, e.g. fit-mechanical's lag fit ending in a dead-zone
valley 8 BIC units lower and diagnose then adding ``torque_offset`` where it added
``viscous_asymmetry``. Neither answer is wrong by the logs; a fleet whose units are fitted on
mixed workers should still not depend on which worker ran which unit.

:func:`pin_blas_kernels` sets ``OPENBLAS_CORETYPE=Haswell`` (AVX2 + FMA, present on every
x86-64 CPU since 2013) before numpy loads, where the CPU has them; a process that imports
pmdcid as a library keeps its BLAS as it is. ``PMDCID_BLAS=default`` (or an
``OPENBLAS_CORETYPE`` of the user's own) turns it off. Worker processes a command starts (a
local Dask cluster) inherit it.
"""

from __future__ import annotations

import os
import platform
import sys

#: the OpenBLAS core type pinned (its kernels need AVX2 and FMA)
CORETYPE = "Haswell"
#: the CPU flags those kernels need
NEEDS = frozenset({"avx2", "fma"})


def _cpu_flags() -> frozenset[str]:
    """The CPU's feature flags (Linux: /proc/cpuinfo), empty where they cannot be read."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return frozenset(line.partition(":")[2].split())
    except OSError:
        pass
    return frozenset()


def pin_blas_kernels() -> bool:
    """Pin OpenBLAS's kernels (module docstring): True when set. Nothing is done when numpy is
    already loaded (too late to matter), the user chose (``PMDCID_BLAS=default`` or their own
    ``OPENBLAS_CORETYPE``), the machine is not x86-64, or its CPU lacks :data:`NEEDS`."""
    if (os.environ.get("PMDCID_BLAS") == "default" or "OPENBLAS_CORETYPE" in os.environ
            or "numpy" in sys.modules):
        return False
    if platform.machine().lower() not in ("x86_64", "amd64") or not NEEDS <= _cpu_flags():
        return False
    os.environ["OPENBLAS_CORETYPE"] = CORETYPE
    return True


__all__ = ["pin_blas_kernels"]
