"""The matrix-free stiffness product against the assembled matrix (issue 28, item 1)."""

from __future__ import annotations

import numpy as np
import pytest
from fem_tools import box_mesh

from railvib_hpc.fem.assemble_serial import assemble_matrix, element_dofs
from railvib_hpc.fem.hex8 import hex8_stiffness
from railvib_hpc.fem.matrix_free import MatrixFreeStiffness, compiled_kernel, element_classes


def _box(nx=6, ny=5, nz=4, hz=0.5):
    """The suite's structured box (``fem_tools.box_mesh``) and each hexahedron's layer index."""
    points, conn = box_mesh(nx, ny, nz, float(nx), float(ny), hz * nz)
    layer = np.floor(points[conn][:, :, 2].mean(axis=1) / hz).astype(int)
    return points, conn, layer


def _relative(a, b):
    return np.abs(a - b).max() / np.abs(b).max()


@pytest.mark.parametrize("formulation", ["bbar", "full", "incompatible"])
def test_product_equals_the_assembled_stiffness_with_layers_and_distorted_elements(formulation):
    points, conn, k = _box()
    rng = np.random.default_rng(1)
    inner = np.flatnonzero((points > 0.5).all(axis=1) & (points[:, :2] < 4.5).all(axis=1)
                           & (points[:, 2] < 1.5))
    points[inner[:5]] += 0.1 * rng.standard_normal((5, 3))      # five distorted nodes
    E = np.where(k < 2, 1.2e8, 3.0e8)
    nu = np.where(k < 2, 0.3, 0.25)
    op = MatrixFreeStiffness(points, conn, E, nu, formulation=formulation)
    K = assemble_matrix(element_dofs(conn, 3), hex8_stiffness(points[conn], E, nu,
                                                              formulation=formulation),
                        3 * len(points))
    u = rng.standard_normal(3 * len(points))
    # round-off of a sum of ~81 terms of size |K| |u|: far below 1e-12
    assert _relative(op.apply(u), K @ u) < 1e-12
    touched = np.isin(conn, inner[:5]).any(axis=1)
    # every distorted element is its own class; the regular ones: one per layer material
    assert op.n_classes == touched.sum() + 2
    # held: the 32-bit element DOF map and one 24 x 24 matrix per class, no more
    assert op.nbytes == (op.dofs.nbytes + op.n_classes * 24 * 24 * 8 + op.bounds.nbytes)
    assert op.dofs.nbytes < 0.2 * (K.data.nbytes + K.indices.nbytes)


def test_constrained_components_are_left_out_as_in_the_reduced_matrix():
    points, conn, _ = _box(4, 3, 3)
    index = np.arange(3 * len(points)).reshape(-1, 3)
    base = points[:, 2] == 0.0
    index[base] = -1                                         # the base fixed
    free = index >= 0
    index[free] = np.arange(free.sum())
    op = MatrixFreeStiffness(points, conn, 1e8, 0.3, dof_index=index)
    K = assemble_matrix(element_dofs(conn, 3), hex8_stiffness(points[conn], 1e8, 0.3),
                        3 * len(points))
    keep = np.flatnonzero(free.ravel())
    Kr = K[keep][:, keep]
    u = np.random.default_rng(2).standard_normal(len(keep))
    assert op.n_dofs == len(keep)
    assert _relative(op.apply(u), Kr @ u) < 1e-12


def test_translated_copies_share_a_class_and_a_scaled_copy_does_not():
    cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                     [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    x = np.stack([cube, cube + [5.0, -3.0, 2.0], 2.0 * cube, cube])
    labels, first = element_classes(x, np.array([0, 0, 0, 1]))
    assert labels[0] == labels[1]
    assert len({labels[0], labels[2], labels[3]}) == 3 and len(first) == 3


def test_compiled_kernel_gives_the_same_product_or_says_what_it_needs():
    points, conn, k = _box(4, 4, 3)
    op = MatrixFreeStiffness(points, conn, np.where(k < 1, 1e8, 2e8), 0.3)
    u = np.random.default_rng(3).standard_normal(op.n_dofs)
    if compiled_kernel() is None:
        with pytest.raises(ImportError, match="needs numba"):
            op.apply_compiled(u)
    else:
        assert _relative(op.apply_compiled(u), op.apply(u)) < 1e-13
