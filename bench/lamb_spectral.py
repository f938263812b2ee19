"""Lamb's 3-D point load at ten Rayleigh wavelengths on spectral hexahedra: a standalone
serial central-difference driver of the SEM operator against Pekeris's closed form.

The setup and the reference of ``bench/lamb_point_far.py`` (the trilinear explicit engine:
-9.4 % at ten wavelengths with 24 hexahedra per wavelength and 2.35 M DOFs):

* quarter model, the symmetry planes ``x = 0`` and ``y = 0`` on rollers, a quarter of the
  vertical load ``P sin^4(pi t / T)`` on the corner node, ``nu = 1/4`` (Pekeris 1955,
  ``tests/transient/lamb.py``), no damping;
* the Rayleigh wavelength ``lambda_R = c_R / f_v``, ``f_v = 1.094 / T`` (the peak of the
  Rayleigh velocity pulse's spectrum), ``--epw`` spectral elements of order ``--order`` per
  ``lambda_R``;
* receivers on the surface along ``x`` at 2, 5 and 10 ``lambda_R``, read through the GLL
  basis at any point (:func:`~railvib_hpc.fem.gll.hex_interpolation`);
* the box: ``x`` to the last receiver plus ``--x-beyond`` wavelengths, ``y`` to ``--width``
  and ``--depth`` wavelengths, the far faces with Lysmer-Kuhlemeyer dashpots (``rho c_P``
  normal, ``rho c_S`` tangential, per node the face's GLL area; exact for normal incidence
  only; the image of the source in ``y_max`` reaches the last receiver after its Rayleigh
  peak for ``width >= 2.4``). The S wave the base reflects at oblique incidence reaches
  the receiver at 10 wavelengths after its Rayleigh peak only from a depth of 3.4
  wavelengths on (``sqrt(10^2 + 4 D^2) / 1.088 > 11.1``; at 1.5 wavelengths the peak there
  was 10-35 % low, measured): uniform elements to ``--fine-depth``, then layers growing by
  ``--growth`` to ``--depth``;
* central differences at ``--step-fraction`` of the stable step (the operator's power
  iteration), the dashpots taken at the mid step (``(M + dt C / 2) v_(n+1/2) = (M - dt C /
  2) v_(n-1/2) + dt f``: diagonal, explicit).

Printed: the mesh, DOFs, step, time per step, and per receiver the peak downward velocity
against Pekeris's (its displacement differentiated on a grid 8 times finer), the error and
the error the dispersion analysis predicts (the harmonic bound of
:func:`~railvib_hpc.fem.dispersion_gll_rayleigh.rayleigh_wavenumber_ratio` at ``f_v``).

Usage::

    python bench/lamb_spectral.py                       # order 6, 1.5 elements (9 points)
    python bench/lamb_spectral.py --order 4 --epw 4     # order 4, 16 points

Measured (2026-12-07, shared 2-core machine; ``docs/spectral.md``): order 6 at 9 points per
wavelength, 225,525 DOFs: +2.08 / +1.47 / +1.44 % at 2 / 5 / 10 wavelengths; order 4 at 16
points, 872,439 DOFs: -0.06 / -0.02 / +0.42 %. The sin^4 pulse carries energy to about twice
``f_v``, so the peak needs ~10 points per wavelength at ``f_v`` even where the dispersion at
``f_v`` alone predicts < 0.2 %. The grading matters: layers growing by 2 from one wavelength
down put order 4 at 16 points 4.8 % off at 5 wavelengths (the coarse layers reflect); by 1.5
from 1.5 wavelengths, as by default, it is the uniform mesh's answer.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "transient"), str(ROOT / "tests" / "fem"), str(ROOT)]

#: ``f_v T`` of the sin^4 pulse (the peak of ``f |S(f)|``; bench/lamb_point_far.py).
F_PEAK_T = 1.09375
#: Poisson's ratio of Pekeris's closed form.
NU = 0.25
#: Receivers' distances from the load [Rayleigh wavelengths].
RADII = (2.0, 5.0, 10.0)
#: Time resolution of the reference before its differentiation (samples per step).
REF_REFINE = 8
#: Soil: shear speed [m/s], density [kg/m^3], the load [N].
C_S, RHO, FORCE = 100.0, 2000.0, 1.0e5
#: Seconds between two progress lines.
PROGRESS_EVERY_S = 5.0


def _levels(h: float, fine: float, depth: float, growth: float) -> np.ndarray:
    """z of the element layers, 0 down to ``-depth``: edge ``h`` to ``fine``, then growing
    by ``growth`` per layer (the Rayleigh wave lives in the fine part; the coarse part only
    delays the body waves' return from the base)."""
    z = [0.0]
    step = h
    while -z[-1] < depth - 1e-9 * h:
        if -z[-1] >= fine - 1e-9 * h:
            step *= growth
        z.append(z[-1] - step)
    return np.array(z[::-1])


def build(args):
    """The mesh, the operator, the inverse mass, the dashpots and the receivers."""
    from railvib_hpc.fem.gll import hex_interpolation
    from railvib_hpc.fem.spectral_kernel import spectral_elasticity
    from railvib_hpc.fem.spectral_mesh import spectral_mesh

    mu = RHO * C_S**2
    lam = 2.0 * mu * NU / (1.0 - 2.0 * NU)
    from lamb import GAMMA

    c_r = C_S / GAMMA
    lam_r = args.wavelength
    h = lam_r / args.epw
    nx = int(math.ceil((RADII[-1] + args.x_beyond) * args.epw))
    ny = int(math.ceil(args.width * args.epw))
    zs = _levels(h, args.fine_depth * lam_r, args.depth * lam_r, args.growth)
    axes = (np.arange(nx + 1) * h, np.arange(ny + 1) * h, zs)
    points, hexes = _tensor_mesh(axes)
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), args.order)
    op = spectral_elasticity(args.order, sm.points, sm.elements, lam, mu, RHO)
    p = sm.points
    held = np.zeros((sm.n_nodes, 3), bool)
    held[np.abs(p[:, 0]) < 1e-9 * h, 0] = True                        # rollers
    held[np.abs(p[:, 1]) < 1e-9 * h, 1] = True
    damping = _dashpots(sm, points, hexes, (axes[0][-1], axes[1][-1], zs[0]), lam, mu)
    receivers = []
    nz = len(zs) - 1
    for r in RADII:
        x = np.array([r * lam_r, 0.0, 0.0])
        e = int(np.clip(x[0] // h, 0, nx - 1)) + nx * (0 + ny * (nz - 1))
        x8 = points[hexes[e]]
        xi = 2.0 * (x - x8[0]) / (x8[6] - x8[0]) - 1.0
        receivers.append((sm.elements[e], hex_interpolation(args.order, xi[None])[0]))
    source = int(np.argmin(np.linalg.norm(p, axis=1)))
    return {"sm": sm, "op": op, "held": held, "damping": damping, "receivers": receivers,
            "source": source, "h": h, "n": (nx, ny, nz), "c_r": c_r, "mu": mu,
            "lam_r": lam_r}


def _tensor_mesh(axes):
    """Hexahedra (gmsh/VTK order) of the tensor grid of ``axes`` (x, y, z coordinates)."""
    nx, ny, nz = (len(a) - 1 for a in axes)
    Z, Y, X = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.stack([X.ravel(), Y.ravel(), Z.ravel()], axis=1)
    k, j, i = (a.ravel() for a in np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx),
                                              indexing="ij"))
    corner = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                       [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]])
    c = np.stack([i, j, k], axis=1)[:, None, :] + corner[None]
    return points, (c[..., 2] * (ny + 1) + c[..., 1]) * (nx + 1) + c[..., 0]


def _dashpots(sm, points, hexes, far, lam, mu):
    """Lysmer dashpots on ``x_max``, ``y_max`` and the base: per node and component
    ``rho c A``, ``A`` the node's GLL quadrature weight on the element faces there
    (``w_i w_j`` times the face's half edges; box elements)."""
    from railvib_hpc.fem.gll import gll_points, lexicographic_index

    n = sm.order
    _, w = gll_points(n)
    ijk = lexicographic_index(n)
    c_p, c_s = math.sqrt((lam + 2.0 * mu) / RHO), math.sqrt(mu / RHO)
    damping = np.zeros((sm.n_nodes, 3))
    x8 = points[hexes]
    lo, hi = x8[:, 0], x8[:, 6]
    for axis, value, side in ((0, far[0], n), (1, far[1], n), (2, far[2], 0)):
        edge = hi[:, axis] if side == n else lo[:, axis]
        on = np.flatnonzero(np.abs(edge - value) < 1e-9 * abs(value))
        local = np.flatnonzero(ijk[:, axis] == side)
        a, b = [d for d in range(3) if d != axis]
        area = (w[ijk[local, a]] * w[ijk[local, b]])[None, :] * (
            (hi[on, a] - lo[on, a]) * (hi[on, b] - lo[on, b]) / 4.0)[:, None]
        nodes = sm.elements[on][:, local]
        for comp in range(3):
            np.add.at(damping[:, comp], nodes.ravel(),
                      (RHO * (c_p if comp == axis else c_s) * area).ravel())
    return damping


def run(args) -> dict:
    from lamb import lamb_displacement
    from wave_cases import smooth_pulse

    from railvib_hpc.fem.spectral_kernel import max_frequency_squared

    t_setup = time.perf_counter()
    b = build(args)
    op, held, c = b["op"], b["held"], b["damping"]
    m = np.repeat(op.mass[:, None], 3, axis=1)
    inv = np.where(held, 0.0, 1.0 / m)
    omega2 = max_frequency_squared(op, inv_mass=inv)
    dt = args.step_fraction * 2.0 / math.sqrt(omega2)
    duration = F_PEAK_T * b["lam_r"] / b["c_r"]
    t_end = RADII[-1] * b["lam_r"] / b["c_r"] + args.after * duration
    steps = int(math.ceil(t_end / dt))
    setup = time.perf_counter() - t_setup
    u = np.zeros((op.n_nodes, 3))
    v = np.zeros_like(u)
    f = np.zeros_like(u)
    keep = np.where(held, 0.0, (m - 0.5 * dt * c) / (m + 0.5 * dt * c))
    gain = np.where(held, 0.0, dt / (m + 0.5 * dt * c))
    history = np.zeros((steps, len(RADII)))
    t0, last = time.perf_counter(), 0.0
    for k in range(steps):
        f[:] = 0.0
        # f = K u - f_ext; f_ext = -P/4 s(t) e_z (downward) on the corner node
        f[b["source"], 2] = FORCE / 4.0 * float(smooth_pulse(k * dt, duration))
        op.add_forces(u, f)
        v *= keep
        v -= gain * f
        u += dt * v
        for j, (nodes, phi) in enumerate(b["receivers"]):
            history[k, j] = phi @ v[nodes, 2]                         # v at (k + 1/2) dt
        now = time.perf_counter() - t0
        if now - last >= PROGRESS_EVERY_S or k == steps - 1:
            last = now
            print(f"  stepping {k + 1}/{steps}: {100 * (k + 1) / steps:5.1f} %  elapsed "
                  f"{now:6.1f} s  ETA {now / (k + 1) * (steps - k - 1):6.1f} s", flush=True)
    wall = time.perf_counter() - t0
    times = (np.arange(steps) + 0.5) * dt
    fine = np.arange(steps * REF_REFINE + REF_REFINE) * dt / REF_REFINE
    rows = []
    for j, r in enumerate(RADII):
        u_ref = lamb_displacement(r * b["lam_r"], fine, FORCE, b["mu"], C_S, duration)
        v_ref = np.interp(times, fine, np.gradient(u_ref, fine))
        v_fe = history[:, j]
        v_fe = -v_fe                                      # downward positive, as Pekeris's
        rows.append({"r": r, "peak_fe": float(v_fe.max()), "peak_ref": float(v_ref.max()),
                     "error": float(v_fe.max() / v_ref.max() - 1.0),
                     "shift_steps": int(np.argmax(v_fe) - np.argmax(v_ref)),
                     "predicted": predicted(args, r)})
    free = int(np.count_nonzero(~held))
    return {"rows": rows, "dofs": 3 * op.n_nodes, "free": free, "dt": dt, "steps": steps,
            "wall": wall, "setup": setup, "per_step": wall / steps, "n": b["n"], "h": b["h"],
            "elements": op.n_elements, "nbytes": op.nbytes}


def predicted(args, r: float) -> float:
    """The harmonic bound of the Rayleigh wave's phase lag at ``f_v`` after ``r``
    wavelengths (axis; central differences at the run's step: its Courant number from
    the grid's critical one)."""
    from railvib_hpc.fem.dispersion_gll import critical_courant
    from railvib_hpc.fem.dispersion_gll_rayleigh import rayleigh_wavenumber_ratio

    courant = args.step_fraction * critical_courant(args.order, NU)
    ratio = float(rayleigh_wavenumber_ratio(args.epw, NU, args.order, "central", courant)[0])
    return float(1.0 - math.cos(2.0 * math.pi * r * (ratio - 1.0)))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--order", type=int, default=6)
    ap.add_argument("--epw", type=float, default=1.5, help="elements per Rayleigh wavelength")
    ap.add_argument("--wavelength", type=float, default=10.0, help="lambda_R [m]")
    ap.add_argument("--width", type=float, default=2.5, help="box half-width [wavelengths]")
    ap.add_argument("--depth", type=float, default=3.5, help="box depth [wavelengths]")
    ap.add_argument("--fine-depth", type=float, default=1.5,
                    help="depth of the uniform elements [wavelengths]")
    ap.add_argument("--growth", type=float, default=1.5,
                    help="growth of the element layers below it (1: uniform)")
    ap.add_argument("--x-beyond", type=float, default=0.6, help="beyond the last receiver")
    ap.add_argument("--after", type=float, default=1.5, help="run on [pulse lengths]")
    ap.add_argument("--step-fraction", type=float, default=0.9)
    args = ap.parse_args(argv)
    res = run(args)
    nx, ny, nz = res["n"]
    print(f"# Lamb 3-D, SEM order {args.order}, {args.epw:g} elements ({args.order * args.epw:g}"
          f" points) per Rayleigh wavelength: {nx} x {ny} x {nz} elements of {res['h']:.4g} m, "
          f"{res['dofs']:,} DOFs ({res['free']:,} free), dashpots on x_max, y_max, base; "
          f"{res['steps']} steps of {res['dt']:.4e} s, {1e3 * res['per_step']:.2f} ms per step "
          f"({res['per_step'] / res['dofs'] * 1e9:.1f} ns per DOF), setup {res['setup']:.1f} s, "
          f"stepping {res['wall']:.1f} s, operator {res['nbytes'] / res['dofs']:.1f} B/DOF")
    print("| receiver | peak v SEM [m/s] | peak v Pekeris [m/s] | error | predicted by the "
          "dispersion | peak time SEM - Pekeris [steps] |")
    print("|---|---|---|---|---|---|")
    for row in res["rows"]:
        print(f"| {row['r']:g} lambda_R | {row['peak_fe']:.4e} | {row['peak_ref']:.4e} | "
              f"{100 * row['error']:+.2f} % | {100 * row['predicted']:.2f} % | "
              f"{row['shift_steps']} |")


if __name__ == "__main__":
    main()
