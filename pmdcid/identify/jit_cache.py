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

import os


def fill() -> list[str]:
    """Compile every kernel function numba serves into its cache; the names compiled."""
    os.environ["PMDCID_JIT"] = "1"  # before the compiled build is looked for (once a process)
    import numpy as np

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
    return ["run", "run_into", "discretize_into", "batch_cost", "dead_zone", "static_friction",
            "friction_curve", "sliding_friction"]  # with the functions they call


def main() -> None:
    print("pmdcid: numba's cache filled: " + ", ".join(fill()))


if __name__ == "__main__":
    main()
