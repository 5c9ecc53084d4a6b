"""The build's one step beyond pyproject.toml: compile the kernel's generated C.

``pmdcid/simulate/_kernel.c`` is generated from the kernel's Python source
(``python -m pmdcid.export.codegen``) and loaded with ctypes by pmdcid/simulate/compiled.py. The
extension is optional: without a C compiler the install goes on and numba's JIT of the same
source serves (about 1 s more per command).
"""

from setuptools import Extension, setup

KERNEL = Extension(
    "pmdcid.simulate._kernel",
    sources=["pmdcid/simulate/_kernel.c"],
    # -O3: 25-35 % faster than -O2 on the stick-slip loop, the same bits; no fused
    # multiply-adds: the same operations, rounded as numba's JIT rounds them
    extra_compile_args=["-std=c99", "-O3", "-ffp-contract=off"],
    optional=True,
)

setup(ext_modules=[KERNEL])
