"""The benchmarks. Imported first by ``python -m bench.NAME`` (and by scripts importing
``bench`` before numpy): OpenBLAS's kernels pinned as the command line pins them
(:mod:`pmdcid.runtime.blas`), so that the figures match the commands' on any x86-64 machine."""

from pmdcid.runtime.blas import pin_blas_kernels

pin_blas_kernels()
