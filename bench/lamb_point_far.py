"""Lamb's 3-D problem at ten wavelengths (issue 28, item 7): a vertical point load on an
elastic half-space, the explicit engine against Pekeris's closed form.

The test suite checks the O(N) engines at ten wavelengths on Lamb's *line* load (plane
strain, ``tests/transient/test_lamb_line.py``): a 3-D quarter model as long and as deep
as that slab (rollers and a fixed base far enough that nothing comes back) would hold some
10^7 DOFs. Here the far faces are perfectly matched layers (``boundary.<face> = "pml"``,
issue 29), which let the box end close to the receivers' line, so the 3-D case fits this
machine:

* quarter model, symmetry planes ``x = 0`` and ``y = 0`` on rollers, a quarter of the load
  on the corner node, ``nu = 1/4`` (Pekeris's closed form, :mod:`lamb`), no damping;
* the load ``P sin^4(pi t / T)``; the Rayleigh wavelength ``lambda_R = c_R / f_v`` with
  ``f_v = 1.094 / T`` (the peak of the Rayleigh velocity pulse's spectrum, as in the line
  test), ``--epw`` hexahedra of ``h`` per ``lambda_R`` (24: the line test's mesh, predicted
  -2.6 % in peak velocity at 10 wavelengths along a grid axis by
  :func:`railvib_hpc.fem.dispersion.propagate`);
* receivers on the surface along ``x`` (the grid axis) at 2, 5 and 10 ``lambda_R``;
* the box: ``x`` to the last receiver plus ``--x-beyond`` wavelengths, ``y`` to
  ``--width`` wavelengths (the image of the source in the ``y_max`` face is then far enough
  that its reflection, however small, reaches the last receiver after the Rayleigh pulse's
  peak: ``sqrt(10^2 + (2 w)^2) >= 11.1`` for ``w >= 2.4``), ``--depth`` wavelengths deep,
  then ``--layer`` elements of PML on ``x_max``, ``y_max`` and the base;
* the explicit engine at its own allowed step (:func:`~railvib_hpc.transient.explicit.
  stability_limit` with the layers).

Printed: per receiver the peak downward velocity of the FE model and of Pekeris's solution
(its displacement differentiated on a grid 8 times finer than the step), their
difference, the difference the grid's dispersion predicts (:func:`predicted_error`), the
Rayleigh pulse's arrival lag (cross-correlation, in steps), and the run's
size, step, time per step and peak memory (``VmHWM`` summed over the ranks).

Usage::

    mpirun -n 2 python bench/lamb_point_far.py                 # 24 per wavelength
    mpirun -n 2 python bench/lamb_point_far.py --epw 12 --width 1.5   # a quick look
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

#: ``f_v T`` of the sin^4 pulse (the peak of ``f |S(f)|``; tests/transient/test_lamb_line.py).
F_PEAK_T = 1.09375
#: Poisson's ratio of Pekeris's closed form.
NU = 0.25
#: Receivers' distances from the load [Rayleigh wavelengths].
RADII = (2.0, 5.0, 10.0)
#: Time resolution of the reference before its differentiation (steps / sample).
REF_REFINE = 8


def peak_rss_gb(comm) -> float:
    """Peak resident memory summed over the ranks [GB]
    (:func:`railvib_hpc.resources.peak_memory_gb`)."""
    from railvib_hpc.resources import peak_memory_gb

    return comm.allreduce(peak_memory_gb())


#: Zeros after the reference before its propagation (no wrap-around of the FFT).
PREDICT_PAD = 4096
#: Seconds between two progress lines.
PROGRESS_EVERY_S = 5.0


def stepping_progress(comm):
    """A ``progress(step, steps)`` that prints percent, elapsed time and ETA on rank 0
    every :data:`PROGRESS_EVERY_S` seconds."""
    t0, last = time.perf_counter(), [0.0]

    def progress(k: int, steps: int) -> None:
        now = time.perf_counter() - t0
        if comm.rank == 0 and (now - last[0] >= PROGRESS_EVERY_S or k == steps):
            last[0] = now
            print(f"  stepping {k}/{steps}: {100 * k / steps:5.1f} %  elapsed {now:7.1f} s  "
                  f"ETA {now / k * (steps - k):7.1f} s", flush=True)
    return progress


def predicted_error(v: np.ndarray, dt: float, h: float, distance: float, c_r: float,
                    courant: float) -> float:
    """The peak error the grid's dispersion predicts for the exact velocity ``v`` (samples at
    ``dt``) after ``distance``: ``v`` carried by :func:`railvib_hpc.fem.dispersion.propagate`
    (the S relation at the Rayleigh wavelength, the mesh check's proxy; lumped mass,
    central differences at ``courant`` = ``c_P dt_step / h``) and shifted back by the exact
    travel time ``distance / c_r``."""
    from railvib_hpc.fem.dispersion import propagate

    padded = np.concatenate([v, np.zeros(PREDICT_PAD)])
    moved = propagate(padded, dt, h, c_r, distance, wave="S", direction="axis", nu=NU,
                      mass="lumped", scheme="central", courant=courant)
    f = np.fft.rfftfreq(padded.size, dt)
    back = np.fft.irfft(np.fft.rfft(moved) * np.exp(2j * np.pi * f * distance / c_r),
                        padded.size)
    return float(back.max() / padded.max() - 1.0)


def run(args, comm) -> dict:
    """Mesh, step and compare (collective); returns the table's numbers (every rank)."""
    from lamb import GAMMA, lamb_displacement
    from pml_cases import RHO, E, run_box
    from wave_cases import box_mesh, smooth_pulse

    from railvib_hpc.petsc_env import init_petsc

    init_petsc([])
    mu = E / (2 * (1 + NU))
    c_s = math.sqrt(mu / RHO)
    c_r = c_s / GAMMA
    h = args.h
    lam_r = args.epw * h
    duration = F_PEAK_T * lam_r / c_r
    inside = (int(math.ceil((RADII[-1] + args.x_beyond) * args.epw)),
              int(math.ceil(args.width * args.epw)), int(math.ceil(args.depth * args.epw)))
    n = (inside[0] + args.layer, inside[1] + args.layer, inside[2] + args.layer)
    t0 = time.perf_counter()
    if comm.rank == 0:
        print(f"meshing and assembling {n[0]} x {n[1]} x {n[2]} hexahedra ...", flush=True)
    mesh = box_mesh(n, tuple(k * h for k in n), origin=(0.0, 0.0, -n[2] * h))
    faces = {"x_min": "roller", "y_min": "roller", "x_max": "pml", "y_max": "pml",
             "base": "pml"}
    receivers = np.array([[r * lam_r, 0.0, 0.0] for r in RADII])
    t_end = RADII[-1] * lam_r / c_r + args.after * duration
    force = args.force
    out = run_box(mesh, faces, args.layer * h, ((0.0, 0.0, 0.0), 2, -force / 4), receivers,
                  t_end, 0.0, comm, extra=(f"materials.subgrade.nu={NU}",),
                  history=lambda t: float(smooth_pulse(t, duration)),
                  progress=stepping_progress(comm))
    wall = time.perf_counter() - t0
    dt, t = out["dt"], out["t"]
    fine = np.arange(len(t) * REF_REFINE) * dt / REF_REFINE
    rows = []
    for j, r in enumerate(RADII):
        if comm.rank == 0:
            u_ref = lamb_displacement(r * lam_r, fine, force, mu, c_s, duration)
            v_fine = np.gradient(u_ref, fine)
            v_ref = v_fine[::REF_REFINE][:len(t)]
            predicted = predicted_error(v_fine, dt / REF_REFINE, h, r * lam_r, c_r,
                                        math.sqrt(3.0) * c_s * dt / h)
        else:
            v_ref = predicted = None
        v_ref, predicted = comm.bcast((v_ref, predicted))
        v_fe = -out["v"][:, j, 2]                  # downward positive, as Pekeris's
        i_fe, i_ref = int(np.argmax(v_fe)), int(np.argmax(v_ref))
        # the Rayleigh pulse: cross-correlation lag within one pulse length of the peak
        win = slice(max(i_ref - int(duration / dt), 0), i_ref + int(duration / dt))
        a, b = v_fe[win], v_ref[win]
        lags = np.arange(-len(a) + 1, len(a))
        lag = int(lags[np.argmax(np.correlate(a, b, mode="full"))])
        rows.append({"r_lambda": r, "r_m": r * lam_r, "peak_fe": float(v_fe[i_fe]),
                     "peak_ref": float(v_ref[i_ref]),
                     "error": float(v_fe[i_fe] / v_ref[i_ref] - 1.0), "lag_steps": lag,
                     "predicted": predicted,
                     "peak_time_steps": i_fe - i_ref})
    return {"rows": rows, "dofs": out["dofs"], "steps": len(t) - 1, "dt": dt,
            "time_per_step": out["time_per_step"], "wall": wall, "lambda_r": lam_r,
            "duration": duration, "box": n, "pml_elements": out["pml_elements"],
            "peak_gb": peak_rss_gb(comm), "ranks": comm.size}


def main(argv=None) -> None:
    from mpi4py import MPI

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epw", type=float, default=24.0,
                    help="hexahedra per Rayleigh wavelength (default 24)")
    ap.add_argument("--h", type=float, default=1.0, help="element size [m]")
    ap.add_argument("--width", type=float, default=2.5,
                    help="the box's half-width inside the layers [wavelengths]")
    ap.add_argument("--depth", type=float, default=1.5,
                    help="the box's depth inside the layers [wavelengths]")
    ap.add_argument("--x-beyond", type=float, default=0.6,
                    help="the box beyond the last receiver [wavelengths]")
    ap.add_argument("--layer", type=int, default=8, help="PML thickness [elements]")
    ap.add_argument("--after", type=float, default=1.5,
                    help="run on after the Rayleigh front reaches the last receiver "
                         "[pulse lengths]")
    ap.add_argument("--force", type=float, default=1e5, help="the load [N]")
    args = ap.parse_args(argv)
    comm = MPI.COMM_WORLD
    res = run(args, comm)
    if comm.rank == 0:
        nx, ny, nz = res["box"]
        print(f"# Lamb 3-D, explicit engine, {res['ranks']} rank(s): box {nx} x {ny} x {nz} "
              f"hexahedra of {args.h:g} m ({args.layer}-element PML on x_max, y_max, base; "
              f"{res['pml_elements']:,} in the layers), {res['dofs']:,} DOFs; lambda_R "
              f"{res['lambda_r']:g} m ({args.epw:g} per wavelength), pulse {res['duration']:.4f}"
              f" s; {res['steps']} steps of {res['dt']:.4e} s, {res['time_per_step']:.3f} s "
              f"per step ({res['time_per_step'] / res['dofs'] * 1e9 * res['ranks']:.0f} "
              f"ns per DOF and rank), wall {res['wall']:.0f} s, peak {res['peak_gb']:.2f} GB")
        print("| receiver | r [m] | peak v FE [m/s] | peak v Pekeris [m/s] | error | "
              "predicted by the dispersion | Rayleigh lag [steps] | "
              "peak time FE - Pekeris [steps] |")
        print("|---|---|---|---|---|---|---|---|")
        for row in res["rows"]:
            print(f"| {row['r_lambda']:g} lambda_R | {row['r_m']:.0f} | {row['peak_fe']:.4e} | "
                  f"{row['peak_ref']:.4e} | {row['error'] * 100:+.2f} % | "
                  f"{row['predicted'] * 100:+.2f} % | {row['lag_steps']} | "
                  f"{row['peak_time_steps']} |")


if __name__ == "__main__":
    main()
