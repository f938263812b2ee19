"""Spectral hexahedra of order 1-8 against the trilinear engine's products: DOFs, memory
held per DOF, time per DOF and step on one core, the memory-bandwidth floor, and the cost
of the same accuracy (2 % peak error at ten wavelengths).

Usage (one core, no MPI)::

    python bench/spectral_bench.py                       # orders 1-8, ~1.5 M DOFs each
    python bench/spectral_bench.py --orders 2 4 --dofs 5e5 --no-accuracy

Per order and geometry (``box``: the axis-aligned blocks, a class number per element;
``general``: the same mesh with per-point factors, as the embankment's shoulders):

* ``ns/DOF`` the compiled force kernel ``f += K u`` plus the fused central-difference update
  (:func:`~railvib_hpc.fem.spectral_kernel.central_difference_update`), the minimum of
  ``--repeat`` steps after a warm-up;
* ``B/DOF held``: the explicit state ``u, v, f`` and ``1/m`` per component (32 B) plus what
  the operator holds (connectivity, classes or factors, the lumped mass);
* ``floor``: the bytes a step must move per DOF in this implementation's two passes (the
  kernel reads ``u`` and the connectivity (and the factors), adds into ``f``; the update
  reads ``f, v, u, 1/m`` and writes ``v, u, f``), over this machine's triad bandwidth
  (one core, ``a = b + s c``, 24 B per element, measured here);
* the trilinear engine's products on a hex8 box of about ``--csr-dofs`` DOFs: the SciPy CSR
  matrix of :func:`~railvib_hpc.fem.hex8.hex8_stiffness` (B-bar) and the matrix-free class
  kernel :meth:`~railvib_hpc.fem.matrix_free.MatrixFreeStiffness.apply_compiled`, each with
  the same update;
* with the accuracy table (default): per order the elements per S wavelength that hold the
  predicted peak error below 2 % after ten wavelengths (:mod:`~railvib_hpc.fem.dispersion_gll`
  at the lumped GLL mass, central differences at 0.9 of the grid's critical step, the worse
  of the axis and the face diagonal; the trilinear lumped grid by :mod:`~railvib_hpc.fem.
  dispersion`), the DOFs per cubic wavelength, the step, and the core-seconds to carry a
  cubic wavelength of soil ten wavelengths on.

The machine is shared by other engineers: the minimum of the repeats is printed, and the
load average with it.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: The triad's arrays [doubles]: 3 x 128 MB, beyond every cache of the machine.
TRIAD_LENGTH = 16_000_000
#: The accuracy target of the comparison: 2 % peak error after ten S wavelengths.
TARGET, WAVELENGTHS = 0.02, 10.0
#: Poisson's ratio of the bench soil.
NU = 0.3
#: The explicit engines' step fraction of the critical step.
STEP_FRACTION = 0.9


def triad_bandwidth(repeat: int = 5) -> float:
    """One core's triad ``a = b + s c`` bandwidth [GB/s], 24 B per element (the STREAM
    convention, no write-allocate counted), compiled, best of ``repeat``."""
    import numba

    @numba.njit(fastmath=True)
    def triad(a, b, c, s):
        for i in range(a.size):
            a[i] = b[i] + s * c[i]

    a, b, c = np.zeros(TRIAD_LENGTH), np.ones(TRIAD_LENGTH), np.ones(TRIAD_LENGTH)
    triad(a, b, c, 1.5)
    best = min(_timed(lambda: triad(a, b, c, 1.5)) for _ in range(repeat))
    return 24.0 * TRIAD_LENGTH / best / 1e9


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _box(n_el: tuple[int, int, int]):
    sys.path.insert(0, str(ROOT / "tests" / "fem"))
    from fem_tools import box_mesh

    return box_mesh(*n_el, *(float(n) for n in n_el))                  # 1 m elements


def spectral_row(order: int, dofs: float, repeat: int, bandwidth: float) -> list[dict]:
    """Time, memory and floor of one order, box and general geometry."""
    from railvib_hpc.fem.spectral_kernel import spectral_elasticity
    from railvib_hpc.fem.spectral_mesh import spectral_mesh

    side = max(2, int(round((dofs / 3.0) ** (1 / 3) / order)))
    points, hexes = _box((2 * side, side, max(1, side // 2)))
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), order)
    rows = []
    for geometry in ("box", "general"):
        op = spectral_elasticity(order, sm.points, sm.elements, 1.0e8, 6.0e7, 2000.0,
                                 geometry=geometry)
        n = sm.n_nodes
        best, kernel, state_bytes = _time_spectral(op, n, repeat)
        ndof = 3 * n
        held = (state_bytes + op.nbytes) / ndof
        geometry_bytes = (op.general_factors.nbytes + op.box_class.nbytes) / ndof
        conn_bytes = (op.box_elements.nbytes + op.general_elements.nbytes) / ndof
        moved = 8 + 16 + conn_bytes + geometry_bytes + 56              # per DOF and step
        rows.append({"order": order, "geometry": geometry, "dofs": ndof, "elements": len(hexes),
                     "ns": best / ndof * 1e9, "kernel_ns": kernel / ndof * 1e9, "held": held,
                     "moved": moved, "floor_ns": moved / bandwidth})
        del op
    return rows


def _time_spectral(op, n: int, repeat: int) -> tuple[float, float, int]:
    """Best time of a step (kernel + update) and of the kernel alone, and the explicit
    state's bytes (``u, v, f, 1/m`` per component)."""
    from railvib_hpc.fem.spectral_kernel import central_difference_update

    rng = np.random.default_rng(0)
    u, v, f = rng.standard_normal((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    inv = np.repeat(1.0 / op.mass[:, None], 3, axis=1)
    dt = 1e-12                                           # keeps the state bounded

    def step():
        op.add_forces(u, f)
        central_difference_update(u, v, f, inv, dt)

    step()
    best = min(_timed(step) for _ in range(repeat))
    kernel = min(_timed(lambda: op.add_forces(u, f)) for _ in range(repeat))  # f grows
    return best, kernel, u.nbytes + v.nbytes + f.nbytes + inv.nbytes


def _time_product(product, n: int, inv: np.ndarray, repeat: int) -> float:
    """Best time of ``f = K u`` by ``product`` plus the update."""
    from railvib_hpc.fem.spectral_kernel import central_difference_update

    rng = np.random.default_rng(0)
    u, v = rng.standard_normal((n, 3)), np.zeros((n, 3))

    def step():
        central_difference_update(u, v, product(u), inv, 1e-12)

    step()
    return min(_timed(step) for _ in range(repeat))


def trilinear_rows(dofs: float, repeat: int, bandwidth: float) -> list[dict]:
    """The trilinear engine's products (CSR and matrix-free classes) plus the update."""
    from railvib_hpc.fem.assemble_serial import assemble_matrix, element_dofs
    from railvib_hpc.fem.hex8 import hex8_lumped_mass_diagonal, hex8_stiffness
    from railvib_hpc.fem.matrix_free import MatrixFreeStiffness

    side = max(2, int(round((dofs / 3.0 / 1.0) ** (1 / 3) / 1.26)))
    points, hexes = _box((2 * side, side, side))
    E, nu, rho = 1.5e8, NU, 2000.0
    x = points[hexes]
    ke = hex8_stiffness(x[:1], E, nu)
    dmap = element_dofs(hexes, 3)
    K = assemble_matrix(dmap, np.broadcast_to(ke, (len(hexes), 24, 24)), 3 * len(points))
    mass = np.zeros(3 * len(points))
    np.add.at(mass, dmap.ravel(), hex8_lumped_mass_diagonal(x, rho).ravel())
    mf = MatrixFreeStiffness(points, hexes, E, nu)
    n = len(points)
    ndof = 3 * n
    inv = (1.0 / mass).reshape(n, 3)
    rows = []
    for name, product, held_op in (
            ("CSR (SciPy)", lambda u: (K @ u.ravel()).reshape(n, 3),
             K.data.nbytes + K.indices.nbytes + K.indptr.nbytes),
            ("matrix-free classes (Numba)", lambda u: mf.apply_compiled(u.ravel()).reshape(n, 3),
             mf.nbytes)):
        best = _time_product(product, n, inv, repeat)
        held = (4 * 8 * ndof + held_op) / ndof
        moved = (12.0 * K.nnz / ndof + 16 if name.startswith("CSR") else
                 (2 * 24 * len(hexes) * 12.0) / ndof + 16) + 56
        rows.append({"order": 1, "geometry": name, "dofs": ndof, "elements": len(hexes),
                     "ns": best / ndof * 1e9, "kernel_ns": np.nan, "held": held,
                     "moved": moved, "floor_ns": moved / bandwidth})
    return rows


def accuracy_rows(orders, ns_per_dof: dict) -> list[dict]:
    """Per order the elements per S wavelength for :data:`TARGET` at :data:`WAVELENGTHS`, and
    the cost to carry a cubic wavelength of soil that far."""
    from functools import partial

    from railvib_hpc.fem import dispersion as trilinear
    from railvib_hpc.fem.dispersion import _cp_over_cs, elements_needed
    from railvib_hpc.fem.dispersion_gll import critical_courant, worst_peak_error
    from railvib_hpc.fem.spectral_advice import BODY_DIRECTIONS

    out = []
    ratio = _cp_over_cs(NU)
    for order in orders:
        t0 = time.perf_counter()
        courant = STEP_FRACTION * critical_courant(order, NU)
        worst = partial(worst_peak_error, order=order, directions=BODY_DIRECTIONS)
        epw = elements_needed(TARGET, WAVELENGTHS, lo=0.25, hi=64.0, worst=worst, nu=NU,
                              schemes=(("none", 0.0), ("central", courant)))
        out.append(_cost_row(f"GLL N = {order}", order, epw, courant, ratio,
                             ns_per_dof.get(order, np.nan), time.perf_counter() - t0))
        print(f"  accuracy of order {order}: {epw:.3g} elements per wavelength "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    courant = STEP_FRACTION * trilinear.critical_courant(NU)
    epw = elements_needed(TARGET, WAVELENGTHS, lo=2.0, hi=200.0, nu=NU, mass="lumped",
                          schemes=(("none", 0.0), ("central", courant)))
    out.append(_cost_row("trilinear B-bar, lumped (today)", 1, epw, courant, ratio,
                         ns_per_dof.get("csr", np.nan), 0.0))
    return out


def _cost_row(name, order, epw, courant, ratio, ns, seconds) -> dict:
    """DOFs per cubic S wavelength ``3 (N epw)^3``; steps to travel ten wavelengths: the
    step ``courant h / c_P``, so ``10 N epw ... `` per wavelength: ``10 epw c_P / (c_S
    courant)``; the core-seconds ``DOFs x steps x ns``."""
    dofs = 3.0 * (order * epw) ** 3
    steps = WAVELENGTHS * epw * ratio / courant
    return {"name": name, "order": order, "epw": epw, "ppw": order * epw,
            "dofs_per_wavelength3": dofs, "steps": steps,
            "core_s": dofs * steps * ns * 1e-9, "seconds": seconds}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--orders", type=int, nargs="+", default=list(range(1, 9)))
    ap.add_argument("--dofs", type=float, default=1.5e6, help="DOFs per timed mesh")
    ap.add_argument("--csr-dofs", type=float, default=6e5, help="DOFs of the trilinear box")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--no-accuracy", action="store_true", help="skip the accuracy table")
    args = ap.parse_args(argv)
    print(f"# load average {os.getloadavg()[0]:.2f} (2 cores, shared)", flush=True)
    bandwidth = triad_bandwidth()
    print(f"# one-core triad bandwidth {bandwidth:.1f} GB/s", flush=True)
    rows = []
    for order in args.orders:
        t0 = time.perf_counter()
        rows += spectral_row(order, args.dofs, args.repeat, bandwidth)
        print(f"  order {order} timed ({time.perf_counter() - t0:.0f} s)", flush=True)
    rows += trilinear_rows(args.csr_dofs, args.repeat, bandwidth)
    print("\n| order | geometry | DOFs | B/DOF held | ns/DOF/step (kernel + update) | "
          "of which kernel | B/DOF moved | bandwidth floor [ns/DOF] |")
    print("|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['order']} | {r['geometry']} | {r['dofs']:,} | {r['held']:.1f} | "
              f"{r['ns']:.1f} | {r['kernel_ns']:.1f} | {r['moved']:.0f} | "
              f"{r['floor_ns']:.2f} |")
    if args.no_accuracy:
        return
    ns = {r["order"]: r["ns"] for r in rows if r["geometry"] == "box"}
    ns["csr"] = next(r["ns"] for r in rows if r["geometry"].startswith("CSR"))
    print(f"\n# the same accuracy: {100 * TARGET:g} % peak error after {WAVELENGTHS:g} S "
          f"wavelengths (worst of axis and face diagonal; semidiscrete and central "
          f"differences at {STEP_FRACTION} of the critical step), nu = {NU}", flush=True)
    acc = accuracy_rows(args.orders, ns)
    print("\n| element | elements per S wavelength | points per S wavelength | DOFs per "
          "wavelength^3 | steps for 10 wavelengths | core-s per wavelength^3 |")
    print("|---|---|---|---|---|---|")
    for r in acc:
        print(f"| {r['name']} | {r['epw']:.3g} | {r['ppw']:.3g} | "
              f"{r['dofs_per_wavelength3']:.3g} | {r['steps']:.3g} | {r['core_s']:.3g} |")


if __name__ == "__main__":
    main()
