"""Distributed assembly of K and M into PETSc MPIAIJ matrices (PETSc code lives here).

Each rank owns a contiguous range of nodes/DOFs (:class:`~railvib_hpc.modal.dofmap.DofMap`).
It builds the exact sparsity pattern of its rows from the node graph (every pair of nodes
sharing an element, expanded to their free DOFs), creates K and M with that pattern in one
``createAIJ(csr=...)`` call each (exact preallocation: no mallocs, K and M share the
pattern), computes the matrices of every element touching one of its nodes in batches and
inserts each batch with one ``setValuesRCV`` call; rows of other ranks and eliminated DOFs
are passed as -1 and ignored, so no entries travel between ranks.
"""

from __future__ import annotations

import time
from collections.abc import Collection
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..errors import MeshError
from ..fem.reference import ElementGeometryError
from ..mesh.model import Mesh
from ..schema import PART_ID
from .dofmap import DofMap
from .elements import element_batches

if TYPE_CHECKING:
    from mpi4py import MPI


@dataclass
class LocalPattern:
    """CSR pattern of the owned rows and the elements that touch the owned nodes."""

    indptr: np.ndarray
    indices: np.ndarray
    hex_mask: np.ndarray
    line_mask: np.ndarray


def local_pattern(mesh: Mesh, dofmap: DofMap, rank: int,
                  parts: Collection[str] | None = None) -> LocalPattern:
    """Sparsity pattern of the rows owned by ``rank`` (pure numpy).

    Built on the node graph (8 x 8 pairs per hexahedron instead of 24 x 24 entries): all DOF
    rows of a node share the node's column list, the free DOFs of its neighbours in order.
    ``parts`` restricts it to the elements of those parts (every owned row keeps its
    diagonal).
    """
    nodes = dofmap.owned_nodes(rank)
    n0, n1 = nodes.start, nodes.stop
    n_nodes = mesh.n_nodes
    free = dofmap.index >= 0
    nfree = free.sum(axis=1)
    first = np.where(nfree > 0, np.where(free, dofmap.index,
                                         np.iinfo(np.int64).max).min(axis=1), 0)
    node_mask = np.zeros(n_nodes, dtype=bool)
    node_mask[nodes] = True
    hex_mask = node_mask[mesh.hexes].any(axis=1)
    line_mask = node_mask[mesh.lines].any(axis=1)
    if parts is not None:
        ids = [PART_ID[p] for p in parts]
        hex_mask &= np.isin(mesh.hex_part, ids)
        line_mask &= np.isin(mesh.line_part, ids)
    # every owned node pairs with itself, so each owned row has its diagonal
    keys = [np.arange(n0, n1, dtype=np.int64) * (n_nodes + 1) - n0 * n_nodes]
    for conn in (mesh.hexes[hex_mask], mesh.lines[line_mask]):
        a = np.broadcast_to(conn[:, :, None], conn.shape + conn.shape[1:])
        b = np.broadcast_to(conn[:, None, :], conn.shape + conn.shape[1:])
        own = (a >= n0) & (a < n1)
        keys.append((a[own] - n0) * np.int64(n_nodes) + b[own])
    ukeys = np.unique(np.concatenate(keys))
    pa, pb = ukeys // n_nodes, ukeys % n_nodes                 # local row node, column node
    width = nfree[pb]
    rowlen = np.bincount(pa, weights=width, minlength=n1 - n0).astype(np.int64)
    node_col_start = np.concatenate(([0], np.cumsum(rowlen)))
    cols_node = (np.repeat(first[pb] - np.cumsum(width) + width, width)
                 + np.arange(int(width.sum())))
    rows_per_node = nfree[n0:n1]
    row_len = np.repeat(rowlen, rows_per_node)
    indptr = np.concatenate(([0], np.cumsum(row_len))).astype(np.int64)
    nnz = int(indptr[-1])
    row_node = np.repeat(np.arange(n1 - n0), rows_per_node)
    entry_row = np.repeat(np.arange(len(row_len)), row_len)
    indices = cols_node[node_col_start[row_node[entry_row]] + np.arange(nnz) - indptr[entry_row]]
    return LocalPattern(indptr, indices.astype(np.int64), hex_mask, line_mask)


def assemble(mesh: Mesh, case: Case, dofmap: DofMap, comm: MPI.Comm,
             parts: Collection[str] | None = None, mass: bool = True):
    """Assemble distributed K and M. Returns ``(K, M, info)`` with timings and counts.

    ``parts`` restricts the elements (and the sparsity pattern) to those parts, e.g. for
    the stiffness of one material; ``mass=False`` assembles K only (M is returned as None).
    The whole model's K (``parts=None``) includes the springs of absorbing faces with
    ``boundary.virtual_thickness > 0`` (:mod:`.boundary`).
    """
    from petsc4py import PETSc

    t0 = time.perf_counter()
    pat = local_pattern(mesh, dofmap, comm.rank, parts)
    hex_mask, line_mask = pat.hex_mask, pat.line_mask
    r0, r1 = dofmap.owned_dofs(comm.rank)
    n_local, n_global = r1 - r0, dofmap.n_dofs
    ip = pat.indptr.astype(PETSc.IntType)
    ix = pat.indices.astype(PETSc.IntType)
    mats = []
    for _ in range(2 if mass else 1):
        A = PETSc.Mat().createAIJ(size=((n_local, n_global), (n_local, n_global)),
                                  csr=(ip, ix, np.zeros(len(ix))), comm=comm)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        mats.append(A)
    K, M = mats if mass else (mats[0], None)
    t1 = time.perf_counter()
    t_kernels = t_insert = 0.0
    add = PETSc.InsertMode.ADD_VALUES
    t_k = time.perf_counter()
    geometry_error = None
    try:
        for batch in element_batches(mesh, case, hex_mask, line_mask, with_mass=mass):
            t_b = time.perf_counter()
            t_kernels += t_b - t_k
            cols = batch.dofs(dofmap.index)
            rows = np.where((cols >= r0) & (cols < r1), cols, -1)  # other ranks' rows: skipped
            rows = np.ascontiguousarray(rows, dtype=PETSc.IntType)
            cols = np.ascontiguousarray(cols, dtype=PETSc.IntType)
            K.setValuesRCV(rows, cols, np.ascontiguousarray(batch.K), addv=add)
            if M is not None and batch.M is not None:
                M.setValuesRCV(rows, cols, np.ascontiguousarray(batch.M), addv=add)
            t_k = time.perf_counter()
            t_insert += t_k - t_b
    except ElementGeometryError as exc:       # local work only so far: no collective missed
        geometry_error = str(exc)
    errors = [e for e in comm.allgather(geometry_error) if e]
    if errors:
        for A in mats:
            A.destroy()
        raise MeshError(f"the mesh cannot be assembled: {errors[0]}; check mesh.file or "
                        "the geometry (mesh_report.json lists the element quality)")
    if parts is None:
        from .boundary import boundary_node_blocks

        insert_node_blocks(K, dofmap, comm.rank, *boundary_node_blocks(mesh, case, "spring"))
    t2 = time.perf_counter()
    for A in mats:
        A.assemble()
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        A.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    t3 = time.perf_counter()
    info = {"pattern": t1 - t0, "element_kernels": t_kernels, "insert": t_insert,
            "final_assembly": t3 - t2, "total": t3 - t0,
            "local_elements": int(hex_mask.sum() + line_mask.sum()),
            "local_hexes": int(hex_mask.sum()), "local_nnz": int(len(ix))}
    return K, M, info


def insert_node_blocks(A, dofmap: DofMap, rank: int, nodes: np.ndarray, blocks: np.ndarray
                       ) -> None:
    """Add 3 x 3 blocks on the translations of single nodes to A (owned rows only).

    The blocks lie on the diagonal node blocks, which every pattern of
    :func:`local_pattern` holds; eliminated DOFs are skipped.
    """
    from petsc4py import PETSc

    if len(nodes) == 0:
        return
    r0, r1 = dofmap.owned_dofs(rank)
    cols = dofmap.index[nodes, :3]
    rows = np.where((cols >= r0) & (cols < r1), cols, -1)
    A.setValuesRCV(np.ascontiguousarray(rows, dtype=PETSc.IntType),
                   np.ascontiguousarray(cols, dtype=PETSc.IntType),
                   np.ascontiguousarray(blocks, dtype=float), addv=PETSc.InsertMode.ADD_VALUES)


def assemble_damping(mesh: Mesh, case: Case, dofmap: DofMap, comm, K, M):
    """The damping matrix C of the full-order model (distributed, K's pattern).

    ``C = C_material + C_dashpots (+ C_pads)`` from ``[damping]`` and ``[boundary]``
    (:mod:`.damping`):

    * ``damping.model = 'rayleigh'``: ``alpha M + beta K`` (the whole K, boundary springs
      included, so that ``Phi^T C Phi = diag(alpha + beta omega^2)`` exactly);
    * ``'per_material'``: ``sum_g alpha_g M_g + beta_g K_g`` over the material groups of
      :func:`.energy.material_groups` (each assembled with its own elements; the rail pads
      take ``modal.damping_ratio``);
    * the Lysmer-Kuhlemeyer dashpots of the absorbing faces (lumped node blocks);
    * ``damping.pads``: the rail pads' dashpots ``pads.cx, cy, cz``.

    Entries depend on global DOF numbers only, so C is the same on any number of ranks.
    Returns ``(C, info)`` with the coefficients used.
    """
    from petsc4py import PETSc

    from .boundary import boundary_node_blocks
    from .damping import material_rayleigh, rayleigh_coefficients

    C = K.duplicate(copy=False)
    C.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    subset = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
    same = PETSc.Mat.Structure.SAME_NONZERO_PATTERN
    info: dict = {"model": case["damping.model"]}
    model = case["damping.model"]
    if model == "rayleigh":
        alpha, beta = rayleigh_coefficients(case["modal.damping_ratio"], case["damping.f1"],
                                            case["damping.f2"])
        C.axpy(beta, K, structure=same)
        C.axpy(alpha, M, structure=same)
        info["alpha"], info["beta"] = alpha, beta
    elif model == "per_material":
        from .elements import material_groups

        coeffs = material_rayleigh(case, list(material_groups(mesh)))
        info["groups"] = coeffs
        for group, parts in material_groups(mesh).items():
            alpha, beta = coeffs[group]
            Kg, Mg, _ = assemble(mesh, case, dofmap, comm, parts=parts, mass=alpha != 0.0)
            C.axpy(beta, Kg, structure=subset)
            if Mg is not None:
                C.axpy(alpha, Mg, structure=subset)
                Mg.destroy()
            Kg.destroy()
    nodes, blocks = boundary_node_blocks(mesh, case, "dashpot")
    insert_node_blocks(C, dofmap, comm.rank, nodes, blocks)
    info["dashpot_nodes"] = len(nodes)
    info["layer_elements"] = insert_layer_damping(C, mesh, case, dofmap, comm.rank)
    if case["damping.pads"]:
        insert_pad_dashpots(C, mesh, case, dofmap, comm.rank)
    C.assemble()
    C.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    C.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    return C, info


def insert_pad_dashpots(C, mesh: Mesh, case: Case, dofmap: DofMap, rank: int) -> None:
    """Add the rail pads' dashpots ``pads.cx, cy, cz`` to C (owned rows; K's pattern)."""
    from petsc4py import PETSc

    from ..fem.spring import spring_matrices
    from .elements import PAD_DIRECTION

    r0, r1 = dofmap.owned_dofs(rank)
    for part, (key, direction) in PAD_DIRECTION.items():
        conn = mesh.lines[mesh.line_part == PART_ID[part]]
        if not len(conn):
            continue
        c = case[f"pads.c{key[1]}"]
        cols = dofmap.index[conn, direction]
        rows = np.where((cols >= r0) & (cols < r1), cols, -1)
        C.setValuesRCV(np.ascontiguousarray(rows, dtype=PETSc.IntType),
                       np.ascontiguousarray(cols, dtype=PETSc.IntType),
                       spring_matrices(c, np.full(len(conn), direction)),
                       addv=PETSc.InsertMode.ADD_VALUES)


def node_block_matrix(K, mesh: Mesh, case: Case, dofmap: DofMap, rank: int, which: str):
    """A matrix with K's pattern holding only the absorbing faces' dashpots
    (``which = 'dashpots'``) or the rail pads' dashpots (``'pads'``); assembled."""
    from petsc4py import PETSc

    from .boundary import boundary_node_blocks

    A = K.duplicate(copy=False)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    if which == "dashpots":
        insert_node_blocks(A, dofmap, rank, *boundary_node_blocks(mesh, case, "dashpot"))
    elif which == "pads":
        insert_pad_dashpots(A, mesh, case, dofmap, rank)
    else:
        raise ValueError(f"which must be 'dashpots' or 'pads', got {which!r}")
    A.assemble()
    return A


def insert_layer_damping(C, mesh: Mesh, case: Case, dofmap: DofMap, rank: int) -> int:
    """Add the graded Caughey layers' damping ``sum_e w_e (alpha M_e + beta K_e)`` to C
    (:func:`.boundary.layer_weights`; ``alpha, beta`` from ``boundary.layer_damping`` at
    ``damping.f1``, ``f2``). Returns the number of elements in the layers."""
    from petsc4py import PETSc

    from .boundary import layer_weights
    from .damping import rayleigh_coefficients

    weights = layer_weights(mesh, case)
    if not weights.any():
        return 0
    alpha, beta = rayleigh_coefficients(case["boundary.layer_damping"], case["damping.f1"],
                                        case["damping.f2"])
    r0, r1 = dofmap.owned_dofs(rank)
    own = np.zeros(mesh.n_nodes, dtype=bool)
    own[dofmap.owned_nodes(rank)] = True
    mask = (weights > 0) & own[mesh.hexes].any(axis=1)
    for batch in element_batches(mesh, case, mask, np.zeros(len(mesh.lines), bool)):
        w = layer_weights(mesh, case, mesh.points[batch.conn].mean(axis=1))
        local = w[:, None, None] * (alpha * batch.M + beta * batch.K)
        cols = batch.dofs(dofmap.index)
        rows = np.where((cols >= r0) & (cols < r1), cols, -1)
        C.setValuesRCV(np.ascontiguousarray(rows, dtype=PETSc.IntType),
                       np.ascontiguousarray(cols, dtype=PETSc.IntType),
                       np.ascontiguousarray(local), addv=PETSc.InsertMode.ADD_VALUES)
    return int((weights > 0).sum())
