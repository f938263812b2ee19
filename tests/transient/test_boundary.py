"""Boundary conditions per truncation face and the damping matrix (step 1 of issue 12)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.errors import CaseError
from railvib_hpc.fem.boundary import face_impedance, wave_speeds
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.model.boundary import (
    BoundaryError,
    boundary_node_blocks,
    face_node_sets,
    problem_dofmap,
)
from railvib_hpc.model.boundary_kinds.absorbing import absorbing_faces
from railvib_hpc.model.damping import rayleigh_coefficients, rayleigh_ratio
from railvib_hpc.model.dofmap import build_dofmap
from railvib_hpc.petsc_env import init_petsc
from railvib_hpc.problem import Problem
from railvib_hpc.schema import BOUNDARY_FACES, PART_ID

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
ALL_ABSORBING = [f"boundary.{f}=absorbing" for f in BOUNDARY_FACES]
comm = MPI.COMM_WORLD


@pytest.fixture(scope="module")
def coarse():
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.mesh.layout import build_layout
    from railvib_hpc.parallel import on_root

    case = load_case(BASELINE, ["mesh.refinement=0.5"])
    return case, on_root(lambda: generate(build_layout(case))[0])


def test_thesis_boundaries_give_the_thesis_constraints(coarse):
    case, mesh = coarse
    for size in (1, 2, 3):
        old, new = build_dofmap(mesh, size), problem_dofmap(mesh, Problem.from_case(case), size)
        assert np.array_equal(old.index, new.index)
        assert np.array_equal(old.dof_offsets, new.dof_offsets)


def test_face_node_sets_split_the_planes(coarse):
    _, mesh = coarse
    sets = face_node_sets(mesh)
    soil = mesh.points[np.unique(mesh.hexes)]
    lo, hi = soil.min(axis=0), soil.max(axis=0)
    for face, axis, value in (("x_min", 0, lo[0]), ("x_max", 0, hi[0]), ("y_min", 1, lo[1]),
                              ("y_max", 1, hi[1]), ("base", 2, lo[2])):
        assert sets[face].size > 0
        assert np.allclose(mesh.points[sets[face], axis], value)


def test_free_and_roller_faces_release_what_they_should(coarse):
    case, mesh = coarse
    base = problem_dofmap(mesh, Problem.from_case(case)).n_dofs
    sets = face_node_sets(mesh)
    free = load_case(BASELINE, ["mesh.refinement=0.5", "boundary.y_min=free"])
    # y_min: the uy of its nodes becomes free (nodes on the fixed base stay fixed)
    on_base = np.isin(sets["y_min"], sets["base"])
    assert problem_dofmap(mesh, Problem.from_case(free)).n_dofs == base + int((~on_base).sum())
    fixed = load_case(BASELINE, ["mesh.refinement=0.5", "boundary.x_max=fixed"])
    released = problem_dofmap(mesh, Problem.from_case(fixed)).index[sets["x_max"]]
    assert (released[:, :3] < 0).all()


def test_dashpots_carry_rho_c_times_the_face_area(coarse):
    _, mesh = coarse
    case = load_case(BASELINE, ["mesh.refinement=0.5", "boundary.base=absorbing"])
    nodes, blocks = boundary_node_blocks(mesh, Problem.from_case(case), "dashpot")
    cp, cs = wave_speeds(200e6, 0.2, 1850.0)
    area = 21.6 * 37.35                                  # soil plan of the thesis model
    assert blocks[:, 2, 2].sum() == pytest.approx(1850.0 * cp * area, rel=1e-12)
    assert blocks[:, 0, 0].sum() == pytest.approx(1850.0 * cs * area, rel=1e-12)
    assert np.abs(blocks[:, 0, 1]).max() < 1e-9 * blocks[:, 0, 0].max()
    assert np.allclose(mesh.points[nodes, 2], mesh.points[:, 2].min())
    # no springs unless a virtual thickness is given
    assert len(boundary_node_blocks(mesh, Problem.from_case(case), "spring")[0]) == 0


def test_inclined_face_impedance_rotates_with_the_normal():
    # unit square in the plane x + z = const, tilted by 45 degrees about y
    s = 1.0 / math.sqrt(2.0)
    x = np.array([[[0, 0, 0], [s, 0, -s], [s, 1, -s], [0, 1, 0]]], float)
    b = face_impedance(x, 3.0, 1.0).sum(axis=1)[0]
    n = np.array([s, 0.0, s])
    expected = 3.0 * np.outer(n, n) + 1.0 * (np.eye(3) - np.outer(n, n))
    assert np.allclose(b, expected, atol=1e-14)


def _column(part: str = "subgrade", nz: int = 10, height: float = 5.0) -> Mesh:
    z = np.linspace(0.0, height, nz + 1)
    xy = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    pts = np.concatenate([np.c_[xy, np.full(4, zk)] for zk in z])
    k = np.arange(nz)[:, None]
    hexes = np.hstack([4 * k + np.arange(4), 4 * (k + 1) + np.arange(4)])
    return Mesh(points=pts, hexes=hexes, hex_part=np.full(nz, PART_ID[part], np.int32),
                lines=np.zeros((0, 2), np.int64), line_part=np.zeros(0, np.int32),
                node_sets={"bottom": np.arange(4)})


def test_absorbing_face_without_soil_is_refused():
    case = load_case(BASELINE, ["boundary.base=absorbing"])
    with pytest.raises(BoundaryError, match=r"boundary.base = 'absorbing'.*part column"):
        absorbing_faces(_column("column"), Problem.from_case(case))
    side = load_case(BASELINE, ["boundary.y_min=absorbing"])
    with pytest.raises(BoundaryError, match=r"boundary.y_min = 'absorbing'.*no element face"):
        absorbing_faces(_column(), Problem.from_case(side))


def test_absorbing_face_without_soil_exits_2_from_the_cli(tmp_path, capsys):
    # the tiny user mesh (a column of ballast, subballast, subgrade) with its bottom
    # element made a slab: the y_max face (derived from the bounding box) cuts concrete
    msh = tmp_path / "slab_column.msh"
    text = (ROOT / "meshes" / "tiny_user_mesh.msh").read_text()
    msh.write_text(text.replace('3 7 "ballast"', '3 7 "slab"'))
    code = run(["modal", str(BASELINE), "--out", str(tmp_path), "--set", f"mesh.file='{msh}'",
                "--set", "boundary.y_max=absorbing"])
    assert code == 2
    err = capsys.readouterr().err
    assert "boundary.y_max = 'absorbing': 1 of its 3 element faces have no soil behind them " \
           "(part slab)" in err and "Traceback" not in err
    assert len(err.strip().splitlines()) == 1
    assert not (tmp_path / "modes.h5").exists()


def test_unknown_boundary_type_is_one_clear_line(capsys):
    with pytest.raises(CaseError, match=r"boundary.base = 'sponge'.*'fixed', 'roller', "
                                        r"'free', 'absorbing'"):
        load_case(BASELINE, ["boundary.base=sponge"])
    assert run(["check", str(BASELINE), "--set", "boundary.x_min=open"]) == 2
    assert "boundary.x_min = 'open'" in capsys.readouterr().err


def test_virtual_thickness_springs_add_the_layer_behind_the_base():
    """Static compression of a laterally confined column on an absorbing base with springs:
    the top settles by F/A (H + t)/(lambda + 2G), as if the soil went t deeper."""
    init_petsc([])
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    from railvib_hpc.model.petsc import assemble

    mesh = _column()
    t = 3.0
    case = load_case(BASELINE, ["boundary.base=absorbing", f"boundary.virtual_thickness={t}"])
    dofmap = build_dofmap(mesh, 1, rules={"all": ("ux", "uy")})
    K, _, _ = assemble(mesh, Problem.from_case(case), dofmap, MPI.COMM_SELF)
    ip, ix, v = K.getValuesCSR()
    Ks = sp.csr_matrix((v, ix, ip), shape=K.getSize())
    f = np.zeros(dofmap.n_dofs)
    top = np.flatnonzero(np.isclose(mesh.points[:, 2], 5.0))
    f[dofmap.index[top, 2]] = -1e3 / 4                  # 1 kN over the 1 m^2 top
    u = spsolve(Ks.tocsc(), f)
    e, nu = 200e6, 0.2
    p_modulus = e * (1 - nu) / ((1 + nu) * (1 - 2 * nu))
    assert u[dofmap.index[top, 2]] == pytest.approx(-1e3 * (5.0 + t) / p_modulus, rel=1e-10)


def test_rayleigh_coefficients_match_the_ratio_at_both_frequencies():
    a, b = rayleigh_coefficients(0.05, 5.0, 50.0)
    w = 2 * np.pi * np.array([5.0, 50.0, math.sqrt(250.0)])
    z = rayleigh_ratio(a, b, w)
    assert z[:2] == pytest.approx([0.05, 0.05], rel=1e-14)
    assert z[2] == pytest.approx(0.05 * 2 * math.sqrt(250.0) / 55.0, rel=1e-12)


def _matvec(A, dofmap, comm_):
    """This rank's rows of ``A x`` for x_i = sin(i) (global DOF numbers)."""
    x = A.createVecRight()
    r0, r1 = dofmap.owned_dofs(comm_.rank)
    x.setArray(np.sin(np.arange(r0, r1, dtype=float)))
    y = A.createVecLeft()
    A.mult(x, y)
    return y.getArray().copy()


@pytest.mark.mpi
@pytest.mark.parametrize("model", ["rayleigh", "per_material"])
def test_damping_matrix_equals_serial(coarse, model):
    init_petsc([])
    from petsc4py import PETSc

    from railvib_hpc.model.petsc import assemble, assemble_damping

    _, mesh = coarse
    case = load_case(BASELINE, ["mesh.refinement=0.5", f"damping.model={model}",
                                "damping.pads=true", "boundary.virtual_thickness=20",
                                *ALL_ABSORBING])
    norms, products = [], []
    for c, dm in ((MPI.COMM_SELF, problem_dofmap(mesh, Problem.from_case(case), 1)),
                  (comm, problem_dofmap(mesh, Problem.from_case(case), comm.size))):
        K, M, _ = assemble(mesh, Problem.from_case(case), dm, c)
        C, info = assemble_damping(mesh, Problem.from_case(case), dm, c, K, M)
        assert info["dashpot_nodes"] > 0
        assert C.getInfo()["mallocs"] == 0
        norms.append([C.norm(PETSc.NormType.FROBENIUS), C.norm(PETSc.NormType.INFINITY),
                      K.norm(PETSc.NormType.FROBENIUS)])
        products.append((_matvec(C, dm, c), dm.owned_dofs(c.rank)))
        for A in (K, M, C):
            A.destroy()
    (full, _), (mine, (r0, r1)) = products
    # element kernels are evaluated once per distinct shape from a representative element
    # that depends on the partition (elements.unique_shapes), so K and M entries agree to
    # the kernels' round-off (measured <= 4e-12 relative; the Frobenius norm of K on 2
    # ranks 1.1e-12), and so do the norms (bound 1e-11); the dashpot blocks exactly:
    assert norms[1] == pytest.approx(norms[0], rel=1e-11)
    # |d(Cx)_i| <= 1e-11 sum_j |C_ij| |x_j| <= 1e-11 ||C||_inf (|x| <= 1)
    assert np.abs(mine - full[r0:r1]).max() <= 1e-11 * norms[0][1]


def test_rayleigh_damping_matrix_is_alpha_m_plus_beta_k_plus_dashpots(coarse):
    init_petsc([])
    from railvib_hpc.model.petsc import assemble, assemble_damping

    _, mesh = coarse
    case = load_case(BASELINE, ["mesh.refinement=0.5", "boundary.base=absorbing"])
    dm = problem_dofmap(mesh, Problem.from_case(case), 1)
    K, M, _ = assemble(mesh, Problem.from_case(case), dm, MPI.COMM_SELF)
    C, info = assemble_damping(mesh, Problem.from_case(case), dm, MPI.COMM_SELF, K, M)
    a, b = rayleigh_coefficients(0.03, 8.0, 40.0)
    assert (info["alpha"], info["beta"]) == pytest.approx((a, b), rel=1e-14)
    x = K.createVecRight()
    x.setArray(np.cos(np.arange(dm.n_dofs, dtype=float)))
    y, k, m = (K.createVecLeft() for _ in range(3))
    C.mult(x, y)
    K.mult(x, k)
    M.mult(x, m)
    diff = y.getArray() - (b * k.getArray() + a * m.getArray())
    nodes, blocks = boundary_node_blocks(mesh, Problem.from_case(case), "dashpot")
    expected = np.zeros(dm.n_dofs)
    idx = dm.index[nodes, :3]
    xv = x.getArray()
    ok = idx >= 0
    for i in range(3):
        for j in range(3):
            both = ok[:, i] & ok[:, j]
            np.add.at(expected, idx[both, i], blocks[both, i, j] * xv[idx[both, j]])
    assert np.abs(diff - expected).max() < 1e-9 * np.abs(y.getArray()).max()


def test_caughey_face_needs_a_layer_and_is_fixed(coarse):
    with pytest.raises(CaseError, match=r"boundary.layer_thickness = 0.0: must be > 0 m for "
                                        r"the caughey face\(s\) base"):
        load_case(BASELINE, ["boundary.base=caughey"])
    from railvib_hpc.model.boundary import layer_weights

    _, mesh = coarse
    # 9 m: the first column of elements at y_min (centroids 6 m from the face) inside, the
    # next (18 m) outside; no centroid at the layer's edge, where round-off decides
    calm = load_case(BASELINE, ["mesh.refinement=0.5", "boundary.y_min=caughey",
                                "boundary.layer_thickness=9"])
    fixed = problem_dofmap(mesh, Problem.from_case(calm)).index[face_node_sets(mesh)["y_min"]]
    assert (fixed[:, :3] < 0).all()
    w = layer_weights(mesh, Problem.from_case(calm))
    y = mesh.points[mesh.hexes].mean(axis=1)[:, 1]
    y0 = mesh.points[np.unique(mesh.hexes), 1].min()
    inside = y - y0 < 9.0
    assert inside.any() and not inside.all()
    assert np.all(w[~inside] == 0) and np.all(w[inside] > 0)
    assert w == pytest.approx(np.where(inside, (1 - (y - y0) / 9.0) ** 2, 0.0))
