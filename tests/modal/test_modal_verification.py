"""Modal analysis against analytic answers, through the distributed PETSc/SLEPc path.

Numbers: ../shared/reference/benchmarks.md section 1 (soil column, beams). Round-off
tolerances: :mod:`railvib_hpc.tolerances` (``modal_cases.eigen_rtol``).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from fem_analytic import timoshenko_frequencies, timoshenko_pinned_frequency
from modal_cases import beam_mesh, column_mesh, eigen_rtol, soil_case, solve, strip_mesh, to_scipy

from railvib_hpc import tolerances
from railvib_hpc.modal.eigen import EigenSolveError

H = 5.8
E_SOIL, NU_SOIL, RHO_SOIL = 200e6, 0.2, 1850.0        # subgrade of the thesis
G_SOIL = E_SOIL / (2 * (1 + NU_SOIL))
C_S = np.sqrt(G_SOIL / RHO_SOIL)                                    # 212.24 m/s
C_P = np.sqrt((E_SOIL * NU_SOIL / ((1 + NU_SOIL) * (1 - 2 * NU_SOIL)) + 2 * G_SOIL) / RHO_SOIL)
SHEAR = [(2 * n - 1) * C_S / (4 * H) for n in (1, 2, 3)]      # 9.148, 27.445, 45.741 Hz
COMPRESSION = C_P / (4 * H)                                     # 14.939 Hz


def test_benchmark_numbers():
    assert pytest.approx((212.24, 346.58), abs=6e-3) == (C_S, C_P)
    assert pytest.approx([9.148, 27.445, 45.741], abs=2e-3) == SHEAR
    assert pytest.approx(14.939, abs=1e-3) == COMPRESSION


@pytest.mark.parametrize("nz", [16, 32, 64])
def test_soil_column_shear_and_compression(nz):
    case = soil_case()
    # shear: only ux free (1-D shear beam); compression: only uz free (constrained modulus)
    shear, Ks, Ms, _ = solve(column_mesh(nz), case, {"bottom": ("ux", "uy", "uz"),
                                                     "all": ("uy", "uz")}, 3)
    comp, Kc, Mc, _ = solve(column_mesh(nz), case, {"bottom": ("ux", "uy", "uz"),
                                                    "all": ("ux", "uy")}, 1)
    # linear elements with consistent mass converge from above with error ~ (k h)^2 / 12,
    # plus the eigenvalue's round-off
    r_s = eigen_rtol(Ks, Ms, shear.eigenvalues, computations=1)
    for f, exact, n, r in zip(shear.frequencies_hz, SHEAR, (1, 2, 3), r_s):
        kh = (2 * n - 1) * np.pi / (2 * H) * (H / nz)
        assert 0 < f / exact - 1 < 1.05 * kh**2 / 24 + r
    kh = np.pi / (2 * H) * (H / nz)
    r_c = eigen_rtol(Kc, Mc, comp.eigenvalues, computations=1)[0]
    assert 0 < comp.frequencies_hz[0] / COMPRESSION - 1 < 1.05 * kh**2 / 24 + r_c


def test_soil_column_converges_at_rate_two():
    case = soil_case()
    sizes, errors = [], []
    for nz in (8, 16, 32, 64):
        res, *_ = solve(column_mesh(nz), case,
                        {"bottom": ("ux", "uy", "uz"), "all": ("uy", "uz")}, 3)
        sizes.append(H / nz)
        errors.append(abs(res.frequencies_hz[2] / SHEAR[2] - 1))
    slope = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.05)


RAIL = dict(E=210e9, nu=0.3, rho=7700.0, A=64.5e-4, Iyy=2010e-8, Izz=326e-8, k=0.34)
G_RAIL = RAIL["E"] / (2 * (1 + RAIL["nu"]))


def rail_case(**extra):
    """The benchmark rail of benchmarks.md: Table I's section (preset ``table1``)."""
    return soil_case(**{"case.preset": "table1", **extra})

VERTICAL_ONLY = ("uy", "rx", "rz")           # keep ux, uz, ry: axial + vertical bending


def test_short_simply_supported_rail_is_timoshenko_not_euler_bernoulli():
    L, n = 0.6, 32
    rules = {"all": VERTICAL_ONLY, "start": ("ux", "uz"), "end": ("uz",)}
    res, *_ = solve(beam_mesh(n, L), rail_case(), rules, 2)
    f1 = res.frequencies_hz[0]
    eb = 1272.0                                              # benchmarks.md, Euler-Bernoulli
    timo = timoshenko_pinned_frequency(1, L, RAIL["E"], G_RAIL, RAIL["k"], RAIL["A"],
                                       RAIL["Iyy"], RAIL["rho"])
    assert f1 < 0.8 * eb                                     # thick beam: far below EB
    assert f1 == pytest.approx(timo, rel=5e-4)               # O(h^2) error ~1.5e-4 at n = 32


def test_long_simply_supported_rail_matches_euler_bernoulli():
    L, n = 20.0, 40
    rules = {"all": VERTICAL_ONLY, "start": ("ux", "uz"), "end": ("uz",)}
    res, *_ = solve(beam_mesh(n, L), rail_case(), rules, 3)
    for mode in (1, 2, 3):
        eb = (mode * np.pi / L) ** 2 / (2 * np.pi) * np.sqrt(RAIL["E"] * RAIL["Iyy"] /
                                                            (RAIL["rho"] * RAIL["A"]))
        # slenderness: shear + rotary inertia lower f by ~ (q r)^2 (1 + E/kG) / 2 < 0.3 %
        assert res.frequencies_hz[mode - 1] == pytest.approx(eb, rel=3e-3)


def test_cantilever_rail_both_planes():
    L, n = 2.0, 32
    res_v, *_ = solve(beam_mesh(n, L), rail_case(), {"all": VERTICAL_ONLY, "start":
                                                     ("ux", "uz", "ry")}, 3)
    exact_v = timoshenko_frequencies(3, L, RAIL["E"], G_RAIL, RAIL["k"], RAIL["A"], RAIL["Iyy"],
                                     RAIL["rho"])
    assert res_v.frequencies_hz[:3] == pytest.approx(exact_v, rel=1e-3)
    assert exact_v[0] == pytest.approx(40.16, abs=0.01)       # EB: 40.78 Hz
    res_h, *_ = solve(beam_mesh(n, L), rail_case(), {"all": ("uz", "rx", "ry"),
                                                     "start": ("ux", "uy", "rz")}, 3)
    exact_h = timoshenko_frequencies(3, L, RAIL["E"], G_RAIL, RAIL["k"], RAIL["A"], RAIL["Izz"],
                                     RAIL["rho"])
    assert res_h.frequencies_hz[:3] == pytest.approx(exact_h, rel=1e-3)


def test_mass_normalised_with_repeated_eigenvalues():
    # square section (Iyy = Izz, ky = kz): every bending frequency is a double eigenvalue
    case = rail_case(**{"sections.rail.izz": 2010e-8, "sections.rail.shear_coefficient_z": 0.34})
    clamped = ("ux", "uy", "uz", "rx", "ry", "rz")
    res, K, M, _ = solve(beam_mesh(24, 2.0), case, {"start": clamped, "all": ("ux", "rx")}, 6)
    lam = res.eigenvalues
    rtol = eigen_rtol(K, M, lam)
    for k in (0, 2, 4):                                # bending pairs, no axial/torsion modes
        assert lam[k] == pytest.approx(lam[k + 1], rel=rtol[k])
    st, phi = res.stats, res.phi
    Ks, Ms = to_scipy(K), to_scipy(M)
    gram_m, gram_k = tolerances.product_error(Ms, phi), tolerances.product_error(Ks, phi)
    assert st["max_orthonormality_error"] <= gram_m.max()          # Phi^T M Phi = I
    assert st["max_stiffness_diag_error"] <= gram_k.max() / lam.max()  # = diag(omega^2)
    assert st["max_relative_residual"] < 1e-8
    assert np.all(np.abs(phi.T @ (Ms @ phi) - np.eye(6)) <= gram_m)
    assert np.all(np.abs(phi.T @ (Ks @ phi) - np.diag(lam)) <= gram_k)


def test_krylov_schur_and_block_lanczos_agree_and_slicing_finds_all():
    mesh = column_mesh(40)
    rules = {"bottom": ("ux", "uy", "uz")}
    block, K, M, _ = solve(mesh, soil_case(), rules, 12, method="block_lanczos")
    ks, *_ = solve(mesh, soil_case(), rules, 12, method="krylovschur")
    rtol = eigen_rtol(K, M, block.eigenvalues)
    assert np.all(np.abs(ks.eigenvalues / block.eigenvalues - 1) <= rtol)
    f = block.frequencies_hz
    fmax = 0.5 * (f[8] + f[9])                          # in a gap: 9 modes below
    rtol = eigen_rtol(K, M, block.eigenvalues[:9])
    for method in ("krylovschur", "block_lanczos"):     # SLEPc slicing, band slicing
        sliced, *_ = solve(mesh, soil_case(), rules, 12, f_max=fmax, method=method)
        assert len(sliced.eigenvalues) == 9
        assert np.all(np.abs(sliced.eigenvalues / block.eigenvalues[:9] - 1) <= rtol)
    # SLEPc slicing with the interval ending inside the double eigenvalue f[9] = f[10]
    # returns wrong vectors (relative residuals ~1); this used to pass silently. How many
    # it returns is the rounding of the inertia at a shift on the eigenvalue itself: 10
    # with OpenBLAS's Haswell, Zen and Sandybridge kernels, 9 with SkylakeX; either way the
    # true residuals refuse them.
    with pytest.raises(EigenSolveError, match=r"\d+ of (9|10|11) modes did not converge: "
                                              r"worst relative residual (\S+) ") as err:
        solve(mesh, soil_case(), rules, 12, f_max=0.5 * (f[9] + f[10]), method="krylovschur")
    worst = float(re.search(r"worst relative residual (\S+) ", str(err.value)).group(1))
    assert worst > np.sqrt(1e-10)                    # wrong vectors, not a loose tolerance


def test_too_many_modes_is_a_clear_error():
    with pytest.raises(EigenSolveError, match="must be smaller than the number of free DOFs"):
        solve(column_mesh(4), soil_case(), {"bottom": ("ux", "uy", "uz")}, 100)


def test_slab_one_element_thick_bends_correctly_with_incompatible_modes():
    """Cylindrical bending of a 0.2 m concrete slab: a 4 m cantilever strip, one
    hexahedron across and through its thickness, 20 along (the building's slabs are one
    element thick in the thesis mesh); uy fixed everywhere, i.e. the strip is part of a
    wide slab (plane strain across, plate modulus E / (1 - nu^2)).

    Vertical bending frequencies against Timoshenko theory with the plate modulus
    (k = 5/6): ``modal.hex_formulation = "incompatible"`` within 1.5 % for the first two
    (the one-element section's shear-deflection error, 1.5 % statically in tests/fem,
    enters the frequency as its square root); B-bar, which averages the bending strain's
    dilatation away, is too soft: 6.4 % low here (in plane strain across; a beam-like
    member one element thick is far softer, x1.2 - x2.1 in tests/fem)."""
    L, b, h = 4.0, 0.2, 0.2
    E, nu, rho = 3.1e10, 0.25, 2500.0            # the thesis's concrete
    G = E / (2 * (1 + nu))
    exact = timoshenko_frequencies(2, L, E / (1 - nu**2), G, 5 / 6, b * h, b * h**3 / 12, rho)
    found = {}
    for form in ("incompatible", "bbar"):
        res, *_ = solve(strip_mesh(20, L, b, h), soil_case(**{"modal.hex_formulation": form}),
                        {"root": ("ux", "uy", "uz"), "all": ("uy",)}, 2)
        found[form] = res.frequencies_hz[:2]
    assert found["incompatible"] == pytest.approx(exact, rel=0.015)
    assert np.all(found["bbar"] < 0.95 * exact)


@pytest.mark.parametrize("setting", ["auto", "never", "always"])
def test_out_of_core_factorization(monkeypatch, setting):
    """A model whose in-core factor does not fit: 'auto' switches MUMPS to out of core (the
    factor really goes to disk here) and gives the in-core eigenvalues; 'never' stops with a
    clear message; 'always' uses it regardless. The PETSc option is removed afterwards.

    The memory situation is simulated: 1 GB available, 100 GB in core, 0.001 GB out of core."""
    from petsc4py import PETSc

    from railvib_hpc.model import factor

    name = "railvib_eig_st_mat_mumps_icntl_22"
    reference, K, M, _ = solve(column_mesh(32), soil_case(), {"bottom": ("ux", "uy", "uz"),
                                                              "all": ("uy", "uz")}, 3)
    seen = []

    def estimate(self, prefix):
        ooc = PETSc.Options().getInt(name, 0) == 1
        seen.append(ooc)
        return 0.001 if ooc else 100.0

    monkeypatch.setattr(factor, "available_memory_gb", lambda comm: 1.0)
    monkeypatch.setattr(factor.ShiftInvertFactor, "_estimate_factor_memory", estimate)
    case = soil_case(**{"modal.out_of_core": setting})
    rules = {"bottom": ("ux", "uy", "uz"), "all": ("uy", "uz")}
    if setting == "never":
        with pytest.raises(EigenSolveError, match=r"modal\.out_of_core = 'never'"):
            solve(column_mesh(32), case, rules, 3, out_of_core=setting)
        assert seen == [False]
    else:
        res, *_ = solve(column_mesh(32), case, rules, 3, out_of_core=setting)
        assert res.stats["out_of_core"] is True
        assert res.stats["factor_memory_gb"] == 0.001
        rtol = eigen_rtol(K, M, reference.eigenvalues)
        assert np.all(np.abs(res.eigenvalues / reference.eigenvalues - 1) <= rtol)
        assert seen == ([False, True] if setting == "auto" else [True])
    assert not PETSc.Options().hasName(name)


def test_out_of_core_that_does_not_fit_either_is_a_clear_error(monkeypatch):
    from petsc4py import PETSc

    from railvib_hpc.model import factor

    monkeypatch.setattr(factor, "available_memory_gb", lambda comm: 1.0)
    monkeypatch.setattr(factor.ShiftInvertFactor, "_estimate_factor_memory",
                        lambda self, prefix: 100.0)
    with pytest.raises(EigenSolveError, match=r"out of core: ~100\.0 GB factor, .* does not "
                                              r"fit either, but 1\.0 GB are available"):
        solve(column_mesh(8), soil_case(), {"bottom": ("ux", "uy", "uz"),
                                            "all": ("uy", "uz")}, 3)
    assert not PETSc.Options().hasName("railvib_eig_st_mat_mumps_icntl_22")
