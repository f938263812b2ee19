"""Distributed assembly of K and M into PETSc MPIAIJ matrices (PETSc code lives here).

Each rank owns a contiguous range of nodes/DOFs (:class:`~railvib_hpc.model.dofmap.DofMap`).
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

from ..errors import MeshError
from ..fem.reference import ElementGeometryError
from ..mesh.model import Mesh
from ..problem import Problem
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


#: Owned nodes per chunk of :func:`local_pattern`: its temporaries (about 1.5 kB per DOF of a
#: chunk) stay bounded, so the assembly's peak is K and its column indices, not the pattern's
#: construction (measured: 3.1 kB per DOF at 0.5 M DOFs with the whole pattern at once).
PATTERN_CHUNK_NODES = 50_000


def local_pattern(mesh: Mesh, dofmap: DofMap, rank: int,
                  parts: Collection[str] | None = None,
                  extra_hexes: np.ndarray | None = None) -> LocalPattern:
    """Sparsity pattern of the rows owned by ``rank`` (pure numpy).

    Built on the node graph (8 x 8 pairs per hexahedron instead of 24 x 24 entries): all DOF
    rows of a node share the node's column list, the free DOFs of its neighbours in order.
    ``parts`` restricts it to the elements of those parts (every owned row keeps its
    diagonal); ``extra_hexes`` (a mask over the hexahedra) adds those elements to them.
    Built by chunks of :data:`PATTERN_CHUNK_NODES` owned nodes; the arrays are of
    PETSc's integer type (``indptr`` int64).
    """
    from petsc4py import PETSc

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
        chosen = np.isin(mesh.hex_part, ids)
        if extra_hexes is not None:
            chosen |= extra_hexes
        hex_mask &= chosen
        line_mask &= np.isin(mesh.line_part, ids)
    conns = (mesh.hexes[hex_mask], mesh.lines[line_mask])
    lengths, pieces = [], []
    for c0 in range(n0, max(n1, n0 + 1), PATTERN_CHUNK_NODES):
        c1 = min(c0 + PATTERN_CHUNK_NODES, n1)
        row_len, cols = _pattern_rows(conns, c0, c1, n_nodes, nfree, first)
        lengths.append(row_len)
        pieces.append(cols.astype(PETSc.IntType))
    row_len = np.concatenate(lengths)
    indptr = np.concatenate(([0], np.cumsum(row_len))).astype(np.int64)
    indices = np.concatenate(pieces) if pieces else np.zeros(0, PETSc.IntType)
    return LocalPattern(indptr, indices, hex_mask, line_mask)


def _pattern_rows(conns, n0: int, n1: int, n_nodes: int, nfree: np.ndarray,
                  first: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row lengths and column indices of the DOF rows of nodes ``[n0, n1)`` (see
    :func:`local_pattern`)."""
    # every node pairs with itself, so each row has its diagonal
    keys = [np.arange(n0, n1, dtype=np.int64) * (n_nodes + 1) - n0 * n_nodes]
    for conn in conns:
        conn = conn[((conn >= n0) & (conn < n1)).any(axis=1)]
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
    starts = np.concatenate(([0], np.cumsum(row_len)))
    nnz = int(starts[-1])
    row_node = np.repeat(np.arange(n1 - n0), rows_per_node)
    entry_row = np.repeat(np.arange(len(row_len)), row_len)
    return row_len, cols_node[node_col_start[row_node[entry_row]] + np.arange(nnz)
                              - starts[entry_row]]


def assemble(mesh: Mesh, problem: Problem, dofmap: DofMap, comm: MPI.Comm,
             parts: Collection[str] | None = None, mass: bool | str = True,
             extra_hexes: np.ndarray | None = None, full_hexes: np.ndarray | None = None):
    """Assemble distributed K and M. Returns ``(K, M, info)`` with timings and counts.

    ``parts`` restricts the elements (and the sparsity pattern) to those parts, e.g. for
    the stiffness of one material (``extra_hexes``: a mask of hexahedra added to them);
    ``mass=False`` assembles K only (M is returned as None);
    ``mass="diagonal"`` (with ``modal.lumped_mass``) stores the lumped M on the diagonal
    alone, not in K's pattern (the explicit engines: 1 kB less per DOF).
    ``full_hexes``: hexahedra integrated with the plain full formulation (the perfectly
    matched layers', :func:`~.elements.element_batches`).
    The whole model's K (``parts=None``) includes the springs of absorbing faces with
    ``boundary.virtual_thickness > 0`` (:mod:`.boundary`).
    """
    from petsc4py import PETSc

    t0 = time.perf_counter()
    pat = local_pattern(mesh, dofmap, comm.rank, parts, extra_hexes)
    hex_mask, line_mask = pat.hex_mask, pat.line_mask
    r0, r1 = dofmap.owned_dofs(comm.rank)
    n_local, n_global = r1 - r0, dofmap.n_dofs
    ip = pat.indptr.astype(PETSc.IntType)
    ix = pat.indices.astype(PETSc.IntType, copy=False)
    del pat                      # (only the masks are needed below)
    diagonal = mass == "diagonal"
    if diagonal and not problem.lumped_mass:
        raise ValueError("mass='diagonal' needs modal.lumped_mass = true")
    mats = []
    for k in range(2 if mass else 1):
        pattern = (ip, ix) if not (diagonal and k == 1) else (
            np.arange(n_local + 1, dtype=PETSc.IntType),
            np.arange(r0, r1, dtype=PETSc.IntType))
        A = PETSc.Mat().createAIJ(size=((n_local, n_global), (n_local, n_global)),
                                  csr=pattern, comm=comm)         # (values zero)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        if diagonal and k == 1:
            # the lumped element masses' exact zeros off the diagonal are not stored
            A.setOption(PETSc.Mat.Option.IGNORE_ZERO_ENTRIES, True)
        mats.append(A)
    K, M = mats if mass else (mats[0], None)
    t1 = time.perf_counter()
    t_kernels = t_insert = 0.0
    add = PETSc.InsertMode.ADD_VALUES
    t_k = time.perf_counter()
    geometry_error = None
    try:
        for batch in element_batches(mesh, problem, hex_mask, line_mask, with_mass=mass,
                                     full_hexes=full_hexes):
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

        insert_node_blocks(K, dofmap, comm.rank,
                           *boundary_node_blocks(mesh, problem, "spring"))
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


def assemble_damping(mesh: Mesh, problem: Problem, dofmap: DofMap, comm, K, M,
                     dashpots: bool = True):
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
    ``dashpots = False`` leaves the dashpots out (the explicit engine takes them apart,
    :func:`.boundary.dashpot_diagonal`; ``info["dashpot_nodes"]`` still counts them).
    Returns ``(C, info)`` with the coefficients used.
    """
    from petsc4py import PETSc

    from .boundary import boundary_node_blocks
    from .damping import material_rayleigh, rayleigh_coefficients

    C = K.duplicate(copy=False)
    C.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    subset = PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN
    same = PETSc.Mat.Structure.SAME_NONZERO_PATTERN
    info: dict = {"model": problem.damping.model}
    model = problem.damping.model
    if model == "rayleigh":
        alpha, beta = rayleigh_coefficients(problem.damping.ratio, problem.damping.f1,
                                            problem.damping.f2)
        C.axpy(beta, K, structure=same)
        # M in K's pattern, or the lumped M on the diagonal alone (assemble(mass="diagonal"))
        C.axpy(alpha, M, structure=same if M.getInfo()["nz_used"] == K.getInfo()["nz_used"]
               else subset)
        info["alpha"], info["beta"] = alpha, beta
    elif model == "per_material":
        from .elements import material_groups

        coeffs = material_rayleigh(problem, list(material_groups(mesh)))
        info["groups"] = coeffs
        for group, parts in material_groups(mesh).items():
            alpha, beta = coeffs[group]
            Kg, Mg, _ = assemble(mesh, problem, dofmap, comm, parts=parts, mass=alpha != 0.0)
            C.axpy(beta, Kg, structure=subset)
            if Mg is not None:
                C.axpy(alpha, Mg, structure=subset)
                Mg.destroy()
            Kg.destroy()
    nodes, blocks = boundary_node_blocks(mesh, problem, "dashpot")
    if dashpots:
        insert_node_blocks(C, dofmap, comm.rank, nodes, blocks)
    info["dashpot_nodes"] = len(nodes)
    info["layer_elements"] = insert_layer_damping(C, mesh, problem, dofmap, comm.rank)
    if problem.damping.pads:
        insert_pad_dashpots(C, mesh, problem, dofmap, comm.rank)
    C.assemble()
    C.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    C.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    return C, info


class RayleighOperator:
    """``C = alpha M + beta K + C_b`` applied, not stored: the context of a PETSc shell
    matrix (``Mat.createPython``) for the explicit engines with a lumped M.

    ``C_b`` holds what is not proportional to M or K: the absorbing faces' dashpots and the
    rail pads' dashpots, in a pattern of the diagonal node blocks and the pad elements only
    (a few entries per DOF instead of K's ~81: 1 kB per DOF less, and
    :func:`stiffness_and_damping` folds ``beta K`` into the stiffness product: one product
    with K per step instead of two).
    """

    def __init__(self, K, m, alpha: float, beta: float, C_b):
        self.K, self.alpha, self.beta, self.C_b = K, float(alpha), float(beta), C_b
        self.m = K.createVecLeft()
        self.m.getArray()[:] = m
        self._w = K.createVecLeft()

    def mult(self, mat, x, y) -> None:
        """``y = C x``."""
        self.K.mult(x, y)
        y.scale(self.beta)
        if self.C_b is not None:
            self.C_b.multAdd(x, y, y)
        if self.alpha != 0.0:
            self._w.pointwiseMult(x, self.m)
            y.axpy(self.alpha, self._w)

    def release(self) -> None:
        """Free the vectors and C_b now (collective; :func:`destroy_damping`). Not the
        shell's ``destroy`` hook: petsc4py calls that during ``PetscFinalize`` for a shell
        still alive at exit, where freeing PETSc objects crashes."""
        for obj in (self.m, self._w, self.C_b):
            if obj is not None:
                obj.destroy()
        self.m = self._w = self.C_b = None


def destroy_damping(C) -> None:
    """Destroy a damping matrix: assembled, or the shell of a :class:`RayleighOperator`
    with what it holds (collective; None is ignored)."""
    if C is None:
        return
    ray = rayleigh_parts(C)
    if ray is not None:
        ray.release()
    C.destroy()


def rayleigh_operator(mesh: Mesh, problem: Problem, dofmap: DofMap, comm, K, m: np.ndarray,
                      dashpots: bool = True):
    """The damping of ``damping.model = 'rayleigh'`` as a shell matrix around K (see
    :class:`RayleighOperator`), or None where the model's C is not of that form
    (another damping model, graded absorbing layers) and must be assembled
    (:func:`assemble_damping`). ``m``: this rank's rows of the lumped mass; ``dashpots``
    as there. Returns ``(C, info)`` as :func:`assemble_damping` does."""
    from petsc4py import PETSc

    from .boundary import boundary_node_blocks, layer_weights
    from .damping import rayleigh_coefficients
    from .elements import PAD_DIRECTION

    if problem.damping.model != "rayleigh" or layer_weights(mesh, problem).any():
        return None, None
    alpha, beta = rayleigh_coefficients(problem.damping.ratio, problem.damping.f1,
                                        problem.damping.f2)
    pads = tuple(PAD_DIRECTION) if problem.damping.pads else ()
    pat = local_pattern(mesh, dofmap, comm.rank, pads)
    r0, r1 = dofmap.owned_dofs(comm.rank)
    n_local, n_global = r1 - r0, dofmap.n_dofs
    C_b = PETSc.Mat().createAIJ(size=((n_local, n_global), (n_local, n_global)),
                                csr=(pat.indptr.astype(PETSc.IntType),
                                     pat.indices.astype(PETSc.IntType),
                                     np.zeros(len(pat.indices))), comm=comm)
    C_b.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    nodes, blocks = boundary_node_blocks(mesh, problem, "dashpot")
    if dashpots:
        insert_node_blocks(C_b, dofmap, comm.rank, nodes, blocks)
    if pads:
        insert_pad_dashpots(C_b, mesh, problem, dofmap, comm.rank)
    C_b.assemble()
    op = RayleighOperator(K, m, alpha, beta, C_b)
    C = PETSc.Mat().createPython(K.getSizes(), op, comm=comm)
    C.setUp()
    info = {"model": "rayleigh", "alpha": alpha, "beta": beta, "dashpot_nodes": len(nodes),
            "layer_elements": 0, "operator": True}
    return C, info


def rayleigh_parts(C) -> RayleighOperator | None:
    """The :class:`RayleighOperator` of a shell C, or None for an assembled C."""
    if C is None or C.getType() != "python":
        return None
    ctx = C.getPythonContext()
    return ctx if isinstance(ctx, RayleighOperator) else None


def stiffness_and_damping(K, C, u, v, out, work) -> None:
    """``out = K u + C v`` (PETSc vectors; ``work`` a spare one): with a
    :class:`RayleighOperator` C as ``K (u + beta v) + C_b v + alpha m v``, one product with
    K."""
    ray = rayleigh_parts(C)
    if ray is None:
        K.mult(u, out)
        if C is not None:
            C.mult(v, work)
            out.axpy(1.0, work)
        return
    work.waxpy(ray.beta, v, u)
    K.mult(work, out)
    if ray.C_b is not None:
        ray.C_b.multAdd(v, out, out)
    if ray.alpha != 0.0:
        work.pointwiseMult(v, ray.m)
        out.axpy(ray.alpha, work)


def insert_pad_dashpots(C, mesh: Mesh, problem: Problem, dofmap: DofMap, rank: int,
                        parts: Collection[str] | None = None) -> None:
    """Add the rail pads' dashpots ``pads.cx, cy, cz`` to C (owned rows; K's pattern); only
    those of the pad parts in ``parts`` when given."""
    from petsc4py import PETSc

    from ..fem.spring import spring_matrices
    from .elements import PAD_DIRECTION

    r0, r1 = dofmap.owned_dofs(rank)
    for part, (key, direction) in PAD_DIRECTION.items():
        conn = mesh.lines[mesh.line_part == PART_ID[part]]
        if not len(conn) or (parts is not None and part not in parts):
            continue
        c = getattr(problem.pads, f"c{key[1]}")
        cols = dofmap.index[conn, direction]
        rows = np.where((cols >= r0) & (cols < r1), cols, -1)
        C.setValuesRCV(np.ascontiguousarray(rows, dtype=PETSc.IntType),
                       np.ascontiguousarray(cols, dtype=PETSc.IntType),
                       spring_matrices(c, np.full(len(conn), direction)),
                       addv=PETSc.InsertMode.ADD_VALUES)


def assemble_partition(mesh: Mesh, problem: Problem, dofmap: DofMap, comm,
                       parts: Collection[str], extra_hexes: np.ndarray | None = None,
                       boundary: bool = False, full_hexes: np.ndarray | None = None):
    """Stiffness and damping of the elements of ``parts`` alone: ``(K_p, C_p)``, C_p in
    K_p's pattern or None when nothing of them damps (collective).

    The implicit partition of the IMEX engine (:mod:`railvib_hpc.transient.imex`): with
    ``damping.model = 'rayleigh'`` ``C_p = beta K_p`` (the mass-proportional ``alpha M``
    stays with the explicit part: it is diagonal and weak at high frequency), with
    ``'per_material'`` ``sum_g beta_g K_g`` over the material groups' elements in ``parts``,
    and the rail pads' dashpots of the pad parts in ``parts`` (``damping.pads``). The
    absorbing faces' dashpots, springs and graded layers are soil: never in a partition.
    ``extra_hexes`` (a mask over the hexahedra) adds single elements of other parts;
    ``boundary`` the absorbing faces' springs and dashpots (their lumped node blocks: a
    face node's small mass on a stiff, heavily damped block would set the explicit step).
    ``full_hexes``: as in :func:`assemble` (the whole model's K must integrate them alike).
    """
    from petsc4py import PETSc

    from .damping import material_rayleigh, rayleigh_coefficients

    parts = tuple(parts)
    K_p, _, _ = assemble(mesh, problem, dofmap, comm, parts=parts, mass=False,
                         extra_hexes=extra_hexes, full_hexes=full_hexes)
    C_p = None
    model = problem.damping.model
    if model == "rayleigh":
        _, beta = rayleigh_coefficients(problem.damping.ratio, problem.damping.f1,
                                        problem.damping.f2)
        if beta != 0.0:
            C_p = K_p.duplicate(copy=True)
            C_p.scale(beta)
    elif model == "per_material":
        from .elements import material_groups

        groups = material_groups(mesh)
        coeffs = material_rayleigh(problem, list(groups))
        for group, group_parts in groups.items():
            mine = [p for p in group_parts if p in parts]
            extra = None
            if extra_hexes is not None:
                extra = extra_hexes & np.isin(mesh.hex_part, [PART_ID[p] for p in group_parts])
            beta = coeffs[group][1]
            if (not mine and (extra is None or not extra.any())) or beta == 0.0:
                continue
            if C_p is None:
                C_p = K_p.duplicate(copy=False)
            K_g, _, _ = assemble(mesh, problem, dofmap, comm, parts=mine, mass=False,
                                 extra_hexes=extra)
            C_p.axpy(beta, K_g, structure=PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
            K_g.destroy()
    from .boundary import boundary_node_blocks
    from .elements import PAD_DIRECTION

    if boundary:
        K_p.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        insert_node_blocks(K_p, dofmap, comm.rank,
                           *boundary_node_blocks(mesh, problem, "spring"))
        K_p.assemble()
        nodes, blocks = boundary_node_blocks(mesh, problem, "dashpot")
        if len(nodes):
            if C_p is None:
                C_p = K_p.duplicate(copy=False)
            C_p.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
            insert_node_blocks(C_p, dofmap, comm.rank, nodes, blocks)
            C_p.assemble()
    if problem.damping.pads and any(p in parts for p in PAD_DIRECTION):
        if C_p is None:
            C_p = K_p.duplicate(copy=False)
        C_p.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
        insert_pad_dashpots(C_p, mesh, problem, dofmap, comm.rank, parts)
        C_p.assemble()
    if C_p is not None:
        C_p.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        C_p.setOption(PETSc.Mat.Option.SYMMETRY_ETERNAL, True)
    return K_p, C_p


def node_block_matrix(K, mesh: Mesh, problem: Problem, dofmap: DofMap, rank: int, which: str):
    """A matrix with K's pattern holding only the absorbing faces' dashpots
    (``which = 'dashpots'``) or the rail pads' dashpots (``'pads'``); assembled."""
    from petsc4py import PETSc

    from .boundary import boundary_node_blocks

    A = K.duplicate(copy=False)
    A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, True)
    if which == "dashpots":
        insert_node_blocks(A, dofmap, rank, *boundary_node_blocks(mesh, problem, "dashpot"))
    elif which == "pads":
        insert_pad_dashpots(A, mesh, problem, dofmap, rank)
    else:
        raise ValueError(f"which must be 'dashpots' or 'pads', got {which!r}")
    A.assemble()
    return A


def insert_layer_damping(C, mesh: Mesh, problem: Problem, dofmap: DofMap, rank: int) -> int:
    """Add the graded Caughey layers' damping ``sum_e w_e (alpha M_e + beta K_e)`` to C
    (:func:`.boundary.layer_weights`; ``alpha, beta`` from ``boundary.layer_damping`` at
    ``damping.f1``, ``f2``). Returns the number of elements in the layers."""
    from petsc4py import PETSc

    from .boundary import layer_weights
    from .damping import rayleigh_coefficients

    weights = layer_weights(mesh, problem)
    if not weights.any():
        return 0
    alpha, beta = rayleigh_coefficients(problem.boundary.layer_damping, problem.damping.f1,
                                        problem.damping.f2)
    r0, r1 = dofmap.owned_dofs(rank)
    own = np.zeros(mesh.n_nodes, dtype=bool)
    own[dofmap.owned_nodes(rank)] = True
    mask = (weights > 0) & own[mesh.hexes].any(axis=1)
    for batch in element_batches(mesh, problem, mask, np.zeros(len(mesh.lines), bool)):
        w = layer_weights(mesh, problem, mesh.points[batch.conn].mean(axis=1))
        local = w[:, None, None] * (alpha * batch.M + beta * batch.K)
        cols = batch.dofs(dofmap.index)
        rows = np.where((cols >= r0) & (cols < r1), cols, -1)
        C.setValuesRCV(np.ascontiguousarray(rows, dtype=PETSc.IntType),
                       np.ascontiguousarray(cols, dtype=PETSc.IntType),
                       np.ascontiguousarray(local), addv=PETSc.InsertMode.ADD_VALUES)
    return int((weights > 0).sum())


def static_receptance(K, M, comm, dof: int, prefix: str) -> float:
    """``u[dof]`` of ``K u = e_dof``: the static receptance of one DOF [m/N] (collective).

    One MUMPS Cholesky factor of K (through
    :class:`~railvib_hpc.model.factor.ShiftInvertFactor` at sigma = 0, with its memory
    check; PETSc options prefix ``prefix``), freed before returning. Used to fit the
    supported track ends (:func:`fit_track_ends`).
    """
    from .factor import ShiftInvertFactor

    r0, r1 = K.getOwnershipRange()
    own = r0 <= dof < r1
    rhs = np.zeros((r1 - r0, 1))
    if own:
        rhs[dof - r0, 0] = 1.0
    op = ShiftInvertFactor(K, M, 0.0, comm, prefix)
    try:
        x = op.solve(rhs)
    finally:
        op.destroy()
    return float(comm.allreduce(float(x[dof - r0, 0]) if own else 0.0))


def fit_track_ends(mesh: Mesh, dofmap: DofMap, problem: Problem, K, M, comm,
                   prefix: str) -> tuple[Problem, str]:
    """The problem with the supported track ends' springs, added to the assembled K, and
    the line that says so (collective; both paths, modal and full-order, call it).

    ``track.end_stiffness = 0``: fitted (:func:`~railvib_hpc.model.track_ends.fit_stiffness`)
    to the static receptance of the modelled track at the first rail's node nearest the
    middle of the box (one static solve of K, whose end sections then hang free from the
    box's rail; PETSc options ``prefix``); a given stiffness is in K already
    (:func:`~railvib_hpc.model.boundary.boundary_node_blocks`). Rigid ends: ``problem``
    unchanged and an empty line.

    Raises
    ------
    ValueError
        A receptance that cannot be measured or fitted, naming ``track.end_stiffness``
        (each stage raises it as its own one-line error).
    """
    import dataclasses

    from .track_ends import (
        far_end_nodes,
        fit_stiffness,
        support_blocks,
        support_nodes,
        winkler_modulus,
    )

    ends = problem.track_ends
    if not ends.supported:
        return problem, ""
    n_far = len(far_end_nodes(mesh, ends))
    where = f"{len(support_nodes(mesh, ends)[0]) - n_far} supports and {n_far} clamped far ends"
    rail = problem.sections["rail"]
    ei = problem.material("rail").E * rail.iyy
    if ends.stiffness > 0:
        return problem, (f"  track ends: supported, {where}, k = {ends.stiffness:.4g} N/m per "
                         "rail (track.end_stiffness)")
    nodes = mesh.rail_nodes()[0]
    rail_x = mesh.points[nodes, 0]
    middle = 0.5 * (ends.box_start + ends.box_end)
    node = int(np.argmin(np.abs(rail_x - middle)))
    dof = int(dofmap.index[nodes[node], 2])
    if dof < 0:
        raise ValueError(
            "track.end_stiffness = 0: the rail's vertical DOF at the middle of the box "
            f"(x = {rail_x[node]:g} m) is constrained, so the receptance to fit the "
            "supported ends to cannot be measured; give track.end_stiffness > 0")
    receptance = static_receptance(K, M, comm, dof, prefix)
    if not receptance > 0:
        raise ValueError(
            f"track.end_stiffness = 0: the modelled track's static receptance at x = "
            f"{rail_x[node]:g} m is {receptance:.4g} m/N (not > 0); give "
            "track.end_stiffness > 0")
    per_bay = max(1, int(round(ends.spacing / float(np.diff(rail_x).min()))))
    try:
        stiffness = fit_stiffness(receptance, problem, ends.spacing, per_bay)
    except ValueError as exc:
        raise ValueError(f"track.end_stiffness = 0: {exc}; give track.end_stiffness > 0"
                         ) from None
    problem = dataclasses.replace(problem, track_ends=dataclasses.replace(
        ends, stiffness=stiffness))
    insert_node_blocks(K, dofmap, comm.rank, *support_blocks(mesh, problem, "spring"))
    K.assemble()
    return problem, (f"  track ends: supported, {where}, k = {stiffness:.4g} N/m per "
                     f"rail fitted to the static receptance {receptance:.4g} m/N at x = "
                     f"{rail_x[node]:g} m (the Winkler beam's modulus "
                     f"{winkler_modulus(receptance, ei):.4g} N/m^2, EI = {ei:.4g} N m^2)")
