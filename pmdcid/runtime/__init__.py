"""The performance and safety plumbing every layer above uses, knowing nothing of motors.

- :mod:`~pmdcid.runtime.cpus`: :func:`~pmdcid.runtime.cpus.pmap`, independent pieces of work
  on the CPUs this process may use without oversubscribing them (``PMDCID_THREADS``).
- :mod:`~pmdcid.runtime.outputs`: what a command writes: atomic writes, the command's
  all-or-nothing transaction, the one output guard, the folder lock of a model's
  read-modify-write, output folders removed again on failure.
- :mod:`~pmdcid.runtime.signals`: SIGTERM, SIGHUP, SIGQUIT as an exception that unwinds (and
  the temporary files in flight removed).
- :mod:`~pmdcid.runtime.progress`: one line per stage on a terminal's stderr.
- :mod:`~pmdcid.runtime.malloc`: the command process's heap (large arrays kept, not remapped).
- :mod:`~pmdcid.runtime.blas`: the command process's BLAS kernels, the same on every x86-64
  machine (``OPENBLAS_CORETYPE``, set before numpy loads).

It sits just above :mod:`pmdcid.errors` and :mod:`pmdcid.notes` and below :mod:`pmdcid.io`
(tests/test_architecture.py). The compiled kernel's loading stays in :mod:`pmdcid.simulate`.
"""
