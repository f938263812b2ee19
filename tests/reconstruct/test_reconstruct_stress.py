"""Element stresses against analytic strain states; rail bending moments; parallel driver."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from reconstruct_cases import box_mesh, histories, read_modes, relative_error
from test_reconstruct_fields import check_xdmf

from railvib_hpc.fem.beam import beam_stiffness, shear_deformation_factors
from railvib_hpc.fem.reference import hex_centre_gradients
from railvib_hpc.problem import Problem, case_from_modes
from railvib_hpc.reconstruct import (
    element_stress,
    hex_materials,
    rail_bending_moment,
    rail_moment_modes,
    rail_section,
    reconstruct_fields,
    stress_from_fields,
)
from railvib_hpc.schema import PART_ID

comm = MPI.COMM_WORLD
MATERIALS = {PART_ID["subgrade"]: (2.0e8, 0.2), PART_ID["slab"]: (3.1e10, 0.25)}
EPS = 1e-4


@pytest.fixture(scope="module")
def mesh():
    return box_mesh(4, 3, 2, distort=0.2)


def _materials(mesh):
    E = np.array([MATERIALS[p][0] for p in mesh.hex_part])
    nu = np.array([MATERIALS[p][1] for p in mesh.hex_part])
    return E, nu


def _linear(mesh, grad, shift=(0.0, 0.0, 0.0)):
    """Displacement u = shift + grad @ x at every node."""
    return np.asarray(shift) + mesh.points @ np.asarray(grad, float).T


def test_centre_gradients_reproduce_linear_fields(mesh):
    g = hex_centre_gradients(mesh.points[mesh.hexes])
    assert np.allclose(g.sum(axis=1), 0.0, atol=1e-12)                # partition of unity
    x = mesh.points[mesh.hexes]
    assert np.allclose(np.einsum("eai,eaj->eij", x, g), np.eye(3), atol=1e-12)


def test_uniaxial_stress_gives_E_eps(mesh):
    E, _ = _materials(mesh)
    vm = np.empty(len(E))
    eq = np.empty(len(E))
    for p, (_, poisson) in MATERIALS.items():
        grad = np.diag([EPS, -poisson * EPS, -poisson * EPS])         # free lateral contraction
        u = _linear(mesh, grad, shift=(0.3, -0.1, 0.2))
        a, b = element_stress(mesh.points, mesh.hexes, mesh.hex_part, MATERIALS, u)
        sel = mesh.hex_part == p
        vm[sel], eq[sel] = a[sel], b[sel]
    assert np.allclose(vm, E * EPS, rtol=1e-10)
    assert np.allclose(eq, EPS, rtol=1e-10)


def test_uniaxial_strain_and_pure_shear(mesh):
    E, nu = _materials(mesh)
    mu = E / (2 * (1 + nu))
    # uniaxial strain (no lateral contraction): sigma_xx - sigma_yy = 2 mu eps
    vm, eq = element_stress(mesh.points, mesh.hexes, mesh.hex_part, MATERIALS,
                            _linear(mesh, np.diag([EPS, 0.0, 0.0])))
    assert np.allclose(vm, 2 * mu * EPS, rtol=1e-10)
    assert np.allclose(vm, E * EPS / (1 + nu), rtol=1e-10)
    assert np.allclose(eq, vm / E, rtol=1e-12)
    # pure shear gamma_xy = EPS: tau = mu gamma, von Mises = sqrt(3) tau
    grad = np.zeros((3, 3))
    grad[0, 1] = EPS
    vm, eq = element_stress(mesh.points, mesh.hexes, mesh.hex_part, MATERIALS,
                            _linear(mesh, grad))
    assert np.allclose(vm, np.sqrt(3) * mu * EPS, rtol=1e-10)
    assert np.allclose(eq, vm / E, rtol=1e-12)
    assert np.allclose(eq, np.sqrt(3) / 2 * EPS / (1 + nu), rtol=1e-10)


def test_rigid_body_motion_is_stress_free(mesh):
    omega = np.array([2e-3, -1e-3, 3e-3])
    skew = np.array([[0, -omega[2], omega[1]], [omega[2], 0, -omega[0]],
                     [-omega[1], omega[0], 0]])
    u = _linear(mesh, skew, shift=(0.01, 0.02, -0.03))              # translation + rotation
    vm, eq = element_stress(mesh.points, mesh.hexes, mesh.hex_part, MATERIALS, u)
    E, _ = _materials(mesh)
    assert np.all(vm < 1e-10 * E * np.abs(omega).max())
    assert np.all(eq < 1e-10 * np.abs(omega).max())


def test_batched_times_and_missing_material(mesh):
    rng = np.random.default_rng(3)
    u = rng.standard_normal((4, mesh.n_nodes, 3)) * 1e-4
    vm, eq = element_stress(mesh.points, mesh.hexes, mesh.hex_part, MATERIALS, u)
    assert vm.shape == (4, len(mesh.hexes))
    for k in range(4):
        a, b = element_stress(mesh.points, mesh.hexes, mesh.hex_part, MATERIALS, u[k])
        assert np.array_equal(a, vm[k]) and np.array_equal(b, eq[k])
    with pytest.raises(ValueError, match="no material"):
        element_stress(mesh.points, mesh.hexes, mesh.hex_part,
                       {PART_ID["slab"]: (1e9, 0.2)}, u[0])


def test_rail_moment_constant_and_linear_curvature():
    x = np.array([0.0, 0.3, 0.55, 0.9, 1.5])
    EI = 4.2e6
    a = 2e-3
    # pure bending w = a x^2 / 2 (psi = a x, ry = -a x): M = EI a, for any shear factor
    for phi in (0.0, 0.3):
        M = rail_bending_moment(x, a * x**2 / 2, -a * x, EI, phi)
        assert np.allclose(M, EI * a, rtol=1e-12)
    # Euler-Bernoulli cubic: M = EI w'' = EI (6 c x + 2 b), linear along the rail
    b, c = 1e-3, -4e-3
    w = c * x**3 + b * x**2
    ry = -(3 * c * x**2 + 2 * b * x)
    M = rail_bending_moment(x, w, ry, EI)
    assert np.allclose(M, EI * (6 * c * x + 2 * b), rtol=1e-12)
    ends = rail_bending_moment(x, w, ry, EI, per_element=True)
    assert ends.shape == (4, 2)
    assert np.allclose(ends[:, 0], EI * (6 * c * x[:-1] + 2 * b))
    assert np.allclose(ends[:, 1], EI * (6 * c * x[1:] + 2 * b))
    # sign: a rail pushed down in the middle (w < 0, concave up) sags: M > 0
    xs = np.linspace(0.0, 1.0, 11)
    w = -1e-3 * np.sin(np.pi * xs)
    ry = 1e-3 * np.pi * np.cos(np.pi * xs)
    assert rail_bending_moment(xs, w, ry, EI)[5] > 0
    # batched over leading axes
    assert rail_bending_moment(x, np.zeros((3, 2, 5)), np.zeros((3, 2, 5)), EI).shape == (3, 2, 5)


def test_rail_moment_of_modes_equals_beam_end_forces(coarse_modes):
    """M at the element ends equals the end moments K_e u_e of the FE rail elements."""
    m = 4
    rail = rail_moment_modes(coarse_modes, m)
    with h5py.File(coarse_modes, "r") as f:
        case = case_from_modes(f)
        trans = f["modes/translation"][:m]
        rot = f["modes/rotation"][:m]
        rot_nodes = f["mesh/rotation_nodes"][()]
        pts = f["mesh/points"][()]
    sec = rail_section(Problem.from_case(case))
    k = rail["x"].shape[1]
    assert rail["moment"].shape == (m, 2, k)
    nodes = rail["nodes"][0]
    full = np.zeros((m, len(pts), 6))
    full[:, :, :3] = trans
    full[:, rot_nodes, 3:] = rot
    x = np.stack([pts[nodes[:-1]], pts[nodes[1:]]], axis=1)
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    K = beam_stiffness(x, sec["E"], sec["G"], sec["A"], sec["I"], sec["I"], 1.0, sec["k"],
                       sec["k"], up)
    ue = np.concatenate([full[:, nodes[:-1]], full[:, nodes[1:]]], axis=2)   # (m, e, 12)
    fe = np.einsum("eij,mej->mei", K, ue)
    # end moment about y: M(0) = f_ry0, M(L) = -f_ry1 (sagging positive, psi = -ry)
    phi_y, _ = shear_deformation_factors(x, sec["E"], sec["G"], sec["A"], sec["I"], sec["I"],
                                         sec["k"], sec["k"])
    w = trans[:, nodes, 2]
    ry = full[:, nodes, 4]
    ends = rail_bending_moment(pts[nodes, 0], w, ry, sec["EI"], phi_y, per_element=True)
    scale = np.abs(ends).max()
    assert np.abs(ends[..., 0] - fe[..., 4]).max() < 1e-8 * scale
    assert np.abs(ends[..., 1] + fe[..., 10]).max() < 1e-8 * scale
    assert relative_error(rail["moment_ends"][:, 0], ends) < 1e-12
    nodal = rail["moment"][:, 0]
    assert np.allclose(nodal[:, 0], ends[:, 0, 0]) and np.allclose(nodal[:, -1], ends[:, -1, 1])
    assert np.allclose(nodal[:, 1:-1], 0.5 * (ends[:, :-1, 1] + ends[:, 1:, 0]))


@pytest.mark.mpi
def test_parallel_stress_equals_serial(coarse_modes, shared_tmp):
    m = 5
    t, q, qd, qdd = histories(30, m, seed=4)
    out = shared_tmp / "fields.h5"
    reconstruct_fields(coarse_modes, out, comm, t, q * 1e2, qd, qdd, steps=np.arange(0, 30, 2))
    with h5py.File(coarse_modes, "r") as f:
        materials = hex_materials(Problem.from_modes(f))
    wanted = [t[4] + 1e-5, t[17], t[28]]                  # -> stored steps 2, 8 (t[16]), 14
    stats = stress_from_fields(out, comm, wanted, materials, attrs={"inputs_sha256": "x"})
    comm.Barrier()
    _, mesh = read_modes(coarse_modes, m)
    with h5py.File(out, "r") as f:
        assert int(f.attrs["stress_complete"]) == 1
        assert f["stress"].attrs["inputs_sha256"] == "x"
        sel = f["stress/steps"][()]
        assert sel.tolist() == [2, 8, 14]
        assert np.allclose(f["stress/time"][()], t[np.arange(0, 30, 2)][sel])
        u = f["fields/displacement"][()][sel]
        vm_ref, eq_ref = element_stress(mesh["points"], mesh["hexes"], mesh["hex_part"],
                                        materials, u)
        assert relative_error(f["stress/von_mises"][()], vm_ref) < 1e-12
        assert relative_error(f["stress/strain_eq"][()], eq_ref) < 1e-12
        stress_times = f["stress/time"][()]
    assert stats["n_times"] == 3 and stats["max_von_mises"] == pytest.approx(vm_ref.max())
    grids, times = check_xdmf(out.with_name("stress.xdmf"), out)
    assert len(grids) == 3 and np.array_equal(times, stress_times)
    with pytest.raises(ValueError, match="outside the stored time range"):
        stress_from_fields(out, comm, [t[-1] + 1.0], materials)
