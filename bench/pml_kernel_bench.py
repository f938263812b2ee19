"""The PML memory step per layer element: the NumPy arrays against the fused Numba loop
(:mod:`railvib_hpc.fem.pml_kernel`), one core.

Usage (single-threaded BLAS; under the shared lock so the timings are the machine's own)::

    OPENBLAS_NUM_THREADS=1 python bench/pml_kernel_bench.py --elements 20000 50000

Times are the process's CPU time (``time.process_time``; one thread, so the wall time on
an idle core, and less disturbed than it when other jobs share the cores). Each line: a
batch of distorted 1 m hexahedra with a quadratic damping profile in all three directions
and ``alpha = 20 1/s``; the time of one :meth:`~railvib_hpc.fem.pml.PmlElements.advance`
(the best of ``--repeat`` steps after warm-up steps, the Numba kernel compiling or loading
its cache in the first) in ns per element and step, the speed-up, the largest difference
of the two forces relative to their largest entry, and the kernel's memory per element
(state and geometry: :attr:`~railvib_hpc.fem.pml.PmlElements.nbytes`).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from railvib_hpc.fem.pml import PmlElements

#: Unit cube's nodes in the hexahedron's order.
CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                 [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
#: Soil of the layer: Lame parameters [Pa] (c_P ~ 300 m/s at 2000 kg/m^3).
LAMBDA, MU = 1e8, 5e7
#: Largest damping [1/s] and frequency shift [1/s] of the layer.
D_MAX, ALPHA = 800.0, 20.0
#: Time step [s] (an explicit step of 1 m soil elements).
DT = 1.5e-3
#: Steps run before timing (the first compiles the Numba kernel or loads it).
WARM_UP = 2


def layer(nel: int, kernel: str, seed: int = 0) -> PmlElements:
    """A kernel of ``nel`` distorted hexahedra with random profile depths."""
    rng = np.random.default_rng(seed)
    x = CUBE[None] + rng.uniform(-0.1, 0.1, (nel, 8, 3))
    depth = rng.random((nel, 8, 3))
    out = PmlElements(x, LAMBDA, MU, D_MAX * depth ** 2, alpha=ALPHA)
    out.kernel = kernel
    return out


def step_time(pml: PmlElements, repeat: int, seed: int = 1) -> tuple[float, np.ndarray]:
    """Best CPU time of one :meth:`advance` [s] and the force of the last step."""
    rng = np.random.default_rng(seed)
    nel = len(pml.lam)
    pml.start(np.zeros((nel, 8, 3)))
    steps = [1e-3 * rng.normal(size=(nel, 8, 3)) for _ in range(WARM_UP + repeat)]
    best = np.inf
    for i, u in enumerate(steps):
        t0 = time.process_time()
        force = pml.advance(u, DT)
        if i >= WARM_UP:
            best = min(best, time.process_time() - t0)
    return best, force


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--elements", type=int, nargs="+", default=[20_000, 50_000])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args(argv)
    print("| elements | NumPy [ns/el-step] | Numba [ns/el-step] | speed-up | "
          "max |df| / max |f| | kernel memory [B/el] |")
    print("|---:|---:|---:|---:|---:|---:|")
    for nel in args.elements:
        t_numpy, f_numpy = step_time(layer(nel, "numpy"), args.repeat)
        fast = layer(nel, "numba")
        t_numba, f_numba = step_time(fast, args.repeat)
        diff = np.abs(f_numba - f_numpy).max() / np.abs(f_numpy).max()
        print(f"| {nel:,} | {t_numpy / nel * 1e9:.0f} | {t_numba / nel * 1e9:.0f} | "
              f"{t_numpy / t_numba:.1f} | {diff:.1e} | {fast.nbytes / nel:.0f} |", flush=True)


if __name__ == "__main__":
    main()
