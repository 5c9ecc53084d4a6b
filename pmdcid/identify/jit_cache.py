"""Fill numba's on-disk cache of the kernel: ``python -m pmdcid.identify.jit_cache``.

Where the compiled C kernel is built (:mod:`pmdcid.simulate.compiled`) no command needs numba;
without it (no C compiler, or ``PMDCID_JIT=1``) the first simulation of a fresh install compiles
the kernel's numba functions, tens of seconds, before numba's cache (``__pycache__`` beside the
sources, :mod:`pmdcid.simulate.cache`) keeps them. ``make install`` runs this once after the
build so that neither a user's first command nor a test pays that: it simulates a short log on
each of the kernel's paths with the JIT forced (voltage and torque, a state buffer passed in,
LuGre, one parameter set or several at once) and calls the physics terms a caller may call
directly from Python, with the argument types they take there.
"""

from __future__ import annotations

import importlib
import os

#: the numba functions called from Python (module, name); what they call (the LuGre loop, the
#: matrix exponential) is compiled, and cached, with them
CALLED = (("pmdcid.simulate.kernel", "_run"), ("pmdcid.simulate.kernel", "_run_into"),
          ("pmdcid.simulate.kernel", "discretize_into"), ("pmdcid.identify.grid", "_batch_cost"),
          ("pmdcid.simulate.terms", "dead_zone"), ("pmdcid.simulate.terms", "static_friction"),
          ("pmdcid.simulate.terms", "friction_curve"),
          ("pmdcid.simulate.terms", "sliding_friction"))


def compiled_names() -> list[str]:
    """The functions of :data:`CALLED` that hold a compiled signature in this process."""
    return [name for mod, name in CALLED
            if getattr(importlib.import_module(mod), name).signatures]


def fill() -> list[str]:
    """Compile every function of :data:`CALLED` into numba's cache (loaded from it where it
    holds them); the names that hold a compiled signature afterwards (:func:`compiled_names`).
    Run in a process that has not simulated yet: the JIT is forced before the compiled build is
    looked for, which happens once a process."""
    os.environ["PMDCID_JIT"] = "1"
    import numpy as np

    from pmdcid.simulate import compiled

    if compiled.load() is not None:
        raise RuntimeError("this process already simulates with the compiled C kernel: run "
                           "python -m pmdcid.identify.jit_cache in a fresh process")

    from pmdcid.identify.grid import batch_cost
    from pmdcid.io import Log
    from pmdcid.simulate import kernel, neutral_values, param_vector, simulate_values, terms
    from pmdcid.synth import PAPER

    vals = {**neutral_values(), **PAPER}
    t = np.arange(400) * 1e-3
    u = np.sign(np.sin(t * 30.0)) * 2.0
    simulate_values(t, u, vals)
    simulate_values(t, u * 0.01, vals, torque_driven=True)
    simulate_values(t, u, {**vals, "sigma0": 1e3, "sigma1": 1.0})  # LuGre on
    p = param_vector(vals)
    kernel.run_kernel(u, 1e-3, p, out=np.empty((len(u), kernel.NSTATE)))
    log = Log("warm.csv", t, {"v": u, "omega": simulate_values(t, u, vals).omega})
    batch_cost(log, [vals, {**vals, "bc": vals["bc"] * 1.1}], {"omega": 0.01})
    terms.dead_zone(p, 0.01)
    terms.static_friction(p)
    terms.friction_curve(p, 0.5)
    terms.sliding_friction(p, 0.5, 1.0)
    return compiled_names()


def main() -> None:
    names = fill()
    missing = [name for _, name in CALLED if name not in names]
    if missing:
        raise SystemExit(f"pmdcid: numba did not compile {', '.join(missing)}")
    print("pmdcid: numba's cache filled: " + ", ".join(names))


if __name__ == "__main__":
    main()
