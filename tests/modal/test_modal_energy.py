"""Per-material strain energies of the modes and the damping they give (modal strain
energy method), through the PETSc path, against a two-layer shear column.

A column of height H, base fixed, only ux free, has shear modes u_n = sin(k_n z),
k_n = (2n - 1) pi / (2H), strain energy density ~ cos^2(k_n z). If its lower half is one
material group and its upper half another (same properties), the lower half's share of the
strain energy is  int_0^{H/2} cos^2 / int_0^H cos^2 = 1/2 + (-1)^(n+1) / ((2n - 1) pi).
"""

from __future__ import annotations

import numpy as np
import pytest
from modal_cases import column_mesh, energy_sum_allowance, soil_case, solve

from railvib_hpc.modal.energy import damping_from_energies, group_strain_energies
from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID

H = 5.8
SAME_AS_SUBGRADE = {"materials.ballast.E": 200e6, "materials.ballast.nu": 0.2,
                    "materials.ballast.rho": 1850.0}
RULES = {"bottom": ("ux", "uy", "uz"), "all": ("uy", "uz")}


def _two_layer(nz: int, **extra):
    mesh = column_mesh(nz, H)
    mesh.hex_part[nz // 2:] = PART_ID["ballast"]            # upper half
    case = soil_case(**SAME_AS_SUBGRADE, **extra)
    res, _, _, dofmap = solve(mesh, case, RULES, 3)
    from mpi4py import MPI

    energies = group_strain_energies(mesh, Problem.from_case(case), dofmap, MPI.COMM_SELF,
                                     res.phi)
    return res, energies, case, (mesh, dofmap)


def _exact_lower_share(n: int) -> float:
    return 0.5 + (-1) ** (n + 1) / ((2 * n - 1) * np.pi)


def test_energies_add_up_to_the_eigenvalues():
    res, energies, case, (mesh, dofmap) = _two_layer(32)
    assert set(energies) == {"subgrade", "ballast"}
    total = energies["subgrade"] + energies["ballast"]
    _, allowed = energy_sum_allowance(mesh, case, dofmap, res.phi)
    assert np.all(np.abs(total - res.eigenvalues) <= allowed)


def test_energies_by_mode_chunks_equal_all_modes_at_once():
    """The modes go through the products a chunk at a time (memory): chunks of 1 and 2
    columns give the energies of one product with every mode to round-off."""
    from mpi4py import MPI

    res, energies, case, (mesh, dofmap) = _two_layer(32)
    _, allowed = energy_sum_allowance(mesh, case, dofmap, res.phi)
    for chunk in (1, 2):
        chunked = group_strain_energies(mesh, Problem.from_case(case), dofmap, MPI.COMM_SELF,
                                        res.phi, chunk)
        for group, e in energies.items():
            assert np.all(np.abs(chunked[group] - e) <= allowed)


def test_layer_shares_converge_to_the_analytic_ones_at_rate_two():
    sizes, errors = [], []
    for nz in (16, 32, 64):
        _, e, _, _ = _two_layer(nz)
        share = e["subgrade"] / (e["subgrade"] + e["ballast"])
        err = np.abs(share - [_exact_lower_share(n) for n in (1, 2, 3)])
        # linear elements: energy errors ~ (k h)^2 / 12 relative; the share moves less
        kh = np.array([(2 * n - 1) * np.pi / (2 * H) * H / nz for n in (1, 2, 3)])
        assert np.all(err < kh**2 / 12)
        sizes.append(H / nz)
        errors.append(err[2])
    slope = np.polyfit(np.log(sizes), np.log(errors), 1)[0]
    assert slope == pytest.approx(2.0, abs=0.1)


def test_strain_energy_damping():
    _, e, case, _ = _two_layer(64, **{"materials.subgrade.damping_ratio": 0.05,
                                   "materials.ballast.damping_ratio": 0.01})
    zeta = damping_from_energies(e, Problem.from_case(case))
    share = np.array([_exact_lower_share(n) for n in (1, 2, 3)])
    kh = np.array([(2 * n - 1) * np.pi / (2 * H) * H / 64 for n in (1, 2, 3)])
    assert zeta == pytest.approx(0.05 * share + 0.01 * (1 - share), abs=0.04 * kh.max()**2 / 12)
    # equal ratios everywhere give exactly that ratio for every mode
    same = soil_case(**{"materials.subgrade.damping_ratio": 0.02,
                        "materials.ballast.damping_ratio": 0.02})
    assert damping_from_energies(e, Problem.from_case(same)) == pytest.approx(np.full(3, 0.02),
                                                                              rel=1e-12)
