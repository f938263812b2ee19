"""Matrix-free stiffness product of hexahedral meshes: one element matrix per element class.

The structured blocks of a site mesh give most hexahedra an identical shape per block, so
the product ``K u = sum_e P_e^T K_e P_e u`` needs only one ``K_e`` per *class* (shape up to
a translation, and material), applied to all the class's elements at once as one GEMM
(docs/transient.md, the matrix-free product):

1. gather ``U = u[dofs]``, shape (nel, 24);
2. per class ``c``: ``F_c = U_c K_c`` (``K_c`` symmetric), a (n_c, 24) x (24, 24) product;
3. scatter-add ``F`` into the result (``np.bincount`` with weights).

Memory: the element DOF map (24 32-bit integers per element, ~32 B per DOF on a hexahedral
mesh with one element per node) and the class matrices, against ~1 kB per DOF for an
assembled 3-D hexahedral stiffness (81 entries per row, 12 bytes each). Work: 1,152 flops
per element in GEMM (48 per DOF) against 162 per DOF in the sparse product, but streamed
from 8 B per element DOF instead of 12 B per matrix entry.

The kernels work on plain arrays (NumPy), so an array library with the same API (a GPU
backend) can run them unchanged. Where Numba is installed (optional, not a dependency),
:meth:`MatrixFreeStiffness.apply_compiled` runs the same gather-multiply-scatter as one
compiled loop over the elements (no (chunk, 24) temporaries). ``bench/matrix_free_bench.py``
measures both against the assembled products (SciPy CSR and PETSc MatMult).

Examples
--------
>>> import numpy as np
>>> from railvib_hpc.fem.matrix_free import MatrixFreeStiffness
>>> x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
...               [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
>>> points = np.vstack([x, x[4:] + [0, 0, 1]])
>>> conn = np.array([[0, 1, 2, 3, 4, 5, 6, 7], [4, 5, 6, 7, 8, 9, 10, 11]])
>>> op = MatrixFreeStiffness(points, conn, E=1e8, nu=0.3)
>>> op.n_classes                                   # two identical unit cubes: one class
1
>>> rigid = np.tile([1.0, 0.0, 0.0], 12)           # a rigid translation: no force
>>> bool(np.abs(op.apply(rigid)).max() < 1e-6)
True
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .assemble_serial import element_dofs
from .hex8 import hex8_stiffness

#: Two elements are one class when their node offsets from node 0 agree to this fraction of
#: the element's size (round-off of generated coordinates is ~1e-15 relative; a genuinely
#: different shape differs by far more).
SHAPE_TOLERANCE = 1e-9
#: Elements per gather-GEMM-scatter chunk: bounds the (chunk, 24) work arrays (~4 MB).
CHUNK_ELEMENTS = 20_000


def element_classes(x: np.ndarray, material: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Group hexahedra by shape (node offsets from node 0) and material.

    Parameters
    ----------
    x
        Nodal coordinates per element, shape (nel, 8, 3).
    material
        An integer material label per element, shape (nel,).

    Returns
    -------
    labels
        The class of each element, shape (nel,), numbered 0..n_classes-1.
    first
        One representative element of each class, shape (n_classes,).
    """
    offsets = (x - x[:, :1, :]).reshape(len(x), 24)
    size = np.abs(offsets).max(axis=1, keepdims=True)
    key = np.round(offsets / (SHAPE_TOLERANCE * np.maximum(size, 1e-300))).astype(np.int64)
    key = np.column_stack([key, np.round(np.log2(np.maximum(size[:, 0], 1e-300))
                                          / SHAPE_TOLERANCE).astype(np.int64),
                           np.asarray(material, dtype=np.int64)])
    _, first, labels = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return labels.reshape(-1), first


class MatrixFreeStiffness:
    """``K u`` of a hexahedral mesh without the assembled matrix.

    Parameters
    ----------
    points
        Node coordinates, shape (n_nodes, 3).
    conn
        Hexahedra, shape (nel, 8), node numbers.
    E, nu
        Young's modulus [Pa] and Poisson's ratio, scalars or one per element.
    formulation
        Hexahedron formulation of :func:`~railvib_hpc.fem.hex8.hex8_stiffness`.
    dof_index
        Optional (n_nodes, 3) map from node components to DOF numbers (-1: constrained, left
        out of the product), as the distributed DOF map's ``index``; default ``3 node + i``.
    """

    def __init__(self, points: ArrayLike, conn: ArrayLike, E: ArrayLike, nu: ArrayLike,
                 formulation: str = "bbar", dof_index: np.ndarray | None = None):
        points = np.asarray(points, dtype=float)
        conn = np.asarray(conn, dtype=np.int64)
        nel = len(conn)
        E = np.broadcast_to(np.asarray(E, dtype=float), (nel,))
        nu = np.broadcast_to(np.asarray(nu, dtype=float), (nel,))
        _, material = np.unique(np.column_stack([E, nu]), axis=0, return_inverse=True)
        x = points[conn]
        labels, first = element_classes(x, material.reshape(-1))
        self.n_classes = len(first)
        self.class_matrices = hex8_stiffness(x[first], E[first], nu[first],
                                             formulation=formulation)
        order = np.argsort(labels, kind="stable")
        self.bounds = np.searchsorted(labels[order], np.arange(self.n_classes + 1))
        if dof_index is None:
            dofs = element_dofs(conn, 3)
            self.n_dofs = 3 * len(points)
        else:
            dofs = dof_index[conn].reshape(nel, 24)
            self.n_dofs = int(dof_index.max()) + 1
        dofs = dofs[order]
        # constrained components point at one extra slot (n_dofs) that is dropped
        self.dofs = np.where(dofs < 0, self.n_dofs, dofs).astype(np.int32)
        # the DOF range each chunk touches: its scatter adds into that window only (elements
        # keep their mesh order within a class, so a chunk's DOFs are close together)
        self.windows = [[(int(self.dofs[e0:min(e0 + CHUNK_ELEMENTS, self.bounds[c + 1])].min()),
                          int(self.dofs[e0:min(e0 + CHUNK_ELEMENTS, self.bounds[c + 1])].max())
                          + 1)
                         for e0 in range(self.bounds[c], self.bounds[c + 1], CHUNK_ELEMENTS)]
                        for c in range(self.n_classes)]

    @property
    def nbytes(self) -> int:
        """Memory the operator holds [B]: the element DOF map and the class matrices."""
        return self.dofs.nbytes + self.class_matrices.nbytes + self.bounds.nbytes

    def apply(self, u: ArrayLike, out: np.ndarray | None = None) -> np.ndarray:
        """``K u`` for a vector of ``n_dofs`` values."""
        u_ext = np.zeros(self.n_dofs + 1)
        u_ext[:self.n_dofs] = u
        f = np.zeros(self.n_dofs + 1)
        for c in range(self.n_classes):
            ke = self.class_matrices[c]
            for e0 in range(self.bounds[c], self.bounds[c + 1], CHUNK_ELEMENTS):
                e1 = min(e0 + CHUNK_ELEMENTS, self.bounds[c + 1])
                idx = self.dofs[e0:e1]
                lo, hi = self.windows[c][(e0 - self.bounds[c]) // CHUNK_ELEMENTS]
                f[lo:hi] += np.bincount((idx - lo).ravel(), weights=(u_ext[idx] @ ke).ravel(),
                                        minlength=hi - lo)
        if out is None:
            return f[:self.n_dofs]
        out[:] = f[:self.n_dofs]
        return out

    def apply_compiled(self, u: ArrayLike) -> np.ndarray:
        """``K u`` by the compiled kernel (:func:`compiled_kernel`; needs Numba)."""
        kernel = compiled_kernel()
        if kernel is None:
            raise ImportError("the compiled matrix-free kernel needs numba "
                              "(pip install numba); apply() needs nothing")
        u_ext = np.zeros(self.n_dofs + 1)
        u_ext[:self.n_dofs] = u
        f = np.zeros(self.n_dofs + 1)
        kernel(u_ext, self.dofs, self.bounds.astype(np.int64), self.class_matrices, f)
        return f[:self.n_dofs]


_KERNEL: list = []


def compiled_kernel():
    """The Numba-compiled gather-multiply-scatter loop, or None without Numba (compiled once
    per process, on first use)."""
    if not _KERNEL:
        try:
            import numba
        except ImportError:
            _KERNEL.append(None)
            return None

        @numba.njit(cache=False, fastmath=False)
        def kernel(u, dofs, bounds, kes, f):            # pragma: no cover (compiled)
            ue = np.empty(24)
            for c in range(len(bounds) - 1):
                ke = kes[c]
                for e in range(bounds[c], bounds[c + 1]):
                    for a in range(24):
                        ue[a] = u[dofs[e, a]]
                    for a in range(24):
                        acc = 0.0
                        for b in range(24):
                            acc += ke[a, b] * ue[b]
                        f[dofs[e, a]] += acc

        _KERNEL.append(kernel)
    return _KERNEL[0]
