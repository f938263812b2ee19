"""Print the modal verification cases (computed vs analytic) through the PETSc/SLEPc path.

Usage: python bench/verification_report.py   (serial, ~10 s). The same cases are asserted in
tests/modal/test_modal_verification.py; this script prints the numbers for the README.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tests" / "modal"), str(ROOT / "tests" / "fem")]

from fem_analytic import timoshenko_frequencies, timoshenko_pinned_frequency  # noqa: E402
from modal_cases import beam_mesh, column_mesh, soil_case, solve  # noqa: E402


def main() -> None:
    E, nu, rho, H = 200e6, 0.2, 1850.0, 5.8
    G = E / (2 * (1 + nu))
    lam = E * nu / ((1 + nu) * (1 - 2 * nu))
    cs, cp = np.sqrt(G / rho), np.sqrt((lam + 2 * G) / rho)
    case = soil_case()
    print(f"Soil column H = 5.8 m (c_S = {cs:.2f} m/s, c_P = {cp:.2f} m/s), relative errors:")
    f1, f2, f3, fc = cs / (4 * H), 3 * cs / (4 * H), 5 * cs / (4 * H), cp / (4 * H)
    print(f"| elements | shear 1 ({f1:.3f} Hz) | shear 2 ({f2:.3f} Hz) | shear 3 ({f3:.3f} Hz) | "
          f"compression ({fc:.3f} Hz) |")
    print("|---|---|---|---|---|")
    sizes, errs = [], []
    for nz in (8, 16, 32, 64):
        sh, *_ = solve(column_mesh(nz), case, {"bottom": ("ux", "uy", "uz"),
                                               "all": ("uy", "uz")}, 3)
        co, *_ = solve(column_mesh(nz), case, {"bottom": ("ux", "uy", "uz"),
                                               "all": ("ux", "uy")}, 1)
        e = [sh.frequencies_hz[k] / ((2 * k + 1) * cs / (4 * H)) - 1 for k in range(3)]
        e.append(co.frequencies_hz[0] / (cp / (4 * H)) - 1)
        sizes.append(H / nz)
        errs.append(e)
        print(f"| {nz} | " + " | ".join(f"{x:.2e}" for x in e) + " |")
    errs = np.array(errs)
    slopes = [np.polyfit(np.log(sizes), np.log(errs[:, k]), 1)[0] for k in range(4)]
    print("| rate (polyfit) | " + " | ".join(f"{s:.3f}" for s in slopes) + " |")

    Er, nur, rr, A, Iy, Iz, k = 210e9, 0.3, 7700.0, 64.5e-4, 2010e-8, 326e-8, 0.34
    Gr = Er / (2 * (1 + nur))
    print("\nRail beams (Timoshenko, shear coefficient 0.34, consistent mass with rotary inertia):")
    print("| case | FE [Hz] | Timoshenko exact [Hz] | rel. error | Euler-Bernoulli [Hz] |")
    print("|---|---|---|---|---|")
    res, *_ = solve(beam_mesh(32, 0.6), case, {"all": ("uy", "rx", "rz"), "start": ("ux", "uz"),
                                               "end": ("uz",)}, 1)
    t = timoshenko_pinned_frequency(1, 0.6, Er, Gr, k, A, Iy, rr)
    print(f"| simply supported L = 0.6 m, mode 1, 32 el. | {res.frequencies_hz[0]:.2f} | "
          f"{t:.2f} | {res.frequencies_hz[0] / t - 1:.1e} | 1272.0 |")
    res, *_ = solve(beam_mesh(32, 2.0), case, {"all": ("uy", "rx", "rz"),
                                               "start": ("ux", "uz", "ry")}, 3)
    ex = timoshenko_frequencies(3, 2.0, Er, Gr, k, A, Iy, rr)
    for m, eb in zip(range(3), (40.78, 255.59, 715.66)):
        print(f"| cantilever L = 2 m, vertical, mode {m + 1}, 32 el. | "
              f"{res.frequencies_hz[m]:.3f} | {ex[m]:.3f} | {res.frequencies_hz[m] / ex[m] - 1:.1e}"
              f" | {eb} |")
    res, *_ = solve(beam_mesh(32, 2.0), case, {"all": ("uz", "rx", "ry"),
                                               "start": ("ux", "uy", "rz")}, 3)
    ex = timoshenko_frequencies(3, 2.0, Er, Gr, k, A, Iz, rr)
    for m in range(3):
        print(f"| cantilever L = 2 m, lateral (Izz), mode {m + 1}, 32 el. | "
              f"{res.frequencies_hz[m]:.3f} | {ex[m]:.3f} | "
              f"{res.frequencies_hz[m] / ex[m] - 1:.1e} | - |")
    case2 = soil_case(**{"sections.rail.izz": 2010e-8, "sections.rail.shear_coefficient_z": 0.34})
    clamped = ("ux", "uy", "uz", "rx", "ry", "rz")
    res, *_ = solve(beam_mesh(24, 2.0), case2, {"start": clamped, "all": ("ux", "rx")}, 6)
    st = res.stats
    f = res.frequencies_hz
    print(f"\nRepeated eigenvalues (square section): pairs {f[0]:.6f}/{f[1]:.6f}, "
          f"{f[2]:.6f}/{f[3]:.6f} Hz; max |Phi^T M Phi - I| = "
          f"{st['max_orthonormality_error']:.1e}, max |Phi^T K Phi - diag| / max(w^2) = "
          f"{st['max_stiffness_diag_error']:.1e}, max residual {st['max_relative_residual']:.1e}")


if __name__ == "__main__":
    main()
