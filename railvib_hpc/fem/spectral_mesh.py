"""The node set of spectral hexahedra of order N built on a trilinear (hex8) mesh.

:func:`spectral_mesh` promotes the hexahedra of a mask to order ``N``: each gets the
``(N + 1)^3`` Gauss-Lobatto-Legendre nodes of :mod:`.gll`, placed through the trilinear map
of its 8 corners (so the embankment's shoulder blocks, which are not boxes, keep their
shape exactly). Nodes are shared with the neighbours **topologically**: the nodes inside an
edge, a face or an element belong to that entity, keyed by its global corner ids in a
canonical orientation, never by rounded coordinates (the site meshes have
coincident-but-distinct nodes at their ties, which must stay apart):

* an edge's ``N - 1`` inner nodes run from its corner with the smaller id to the larger;
* a face's ``(N - 1)^2`` inner nodes are numbered in the frame whose origin is the face's
  corner with the smallest id, whose first axis points to the origin's face neighbour with
  the smaller id and whose second axis to the other (both elements that share a face see
  the same frame, whatever their own orientation);
* an element's ``(N - 1)^3`` inner nodes are its own.

The original nodes keep their numbers ``0 .. n_nodes - 1`` (the corners of the spectral
elements are among them, so line elements, node sets and probes stay valid); the new nodes
follow: first the edges', then the faces', then the elements' inner nodes.

**Local node order** of an element (:data:`SpectralMesh.elements`): lexicographic,
``a = i + (N + 1) j + (N + 1)^2 k`` with ``i, j, k = 0 .. N`` the GLL indices along the
reference axes ``xi`` (gmsh/VTK corner 0 -> 1), ``eta`` (0 -> 3) and ``zeta`` (0 -> 4);
corner ``c`` of the hexahedron is local node :data:`corner_positions` ``(N)[c]``.

**Interfaces with hexahedra left at order 1.** On an edge or a face shared between a
promoted and a non-promoted hexahedron, the promoted side's nodes that are not corners are
*constrained* to the linear (edge) or bilinear (face) interpolation of the corners
(:attr:`SpectralMesh.slaves`, ``masters``, ``weights``; ``u_s = sum_m w_sm u_m``). The
promoted element's trace there is then the bilinear function of the face's corners, which
is exactly the trilinear neighbour's trace (both are bilinear in the face's parameters,
and the bilinear interpolant of four corner values is unique): the global space is
conforming and the coupling is a plain restriction of it, no mortar.

*Energy stability.* With ``P`` the prolongation from the free DOFs (every node that is not
a slave) to all, ``u = P u_r``, the reduced stiffness ``K_r = P^T K P`` is symmetric
positive semi-definite (``u_r^T K_r u_r = (P u_r)^T K (P u_r) >= 0``). The mass is lumped
on the reduced space by the row sums of ``P^T M P``: since the weights of every slave sum
to 1 (``P 1 = 1``), ``P^T M P 1 = P^T m``: each slave's diagonal mass goes to its masters
with its weights, which lie in (0, 1), so ``M_r = diag(P^T m)`` is positive
(:func:`condense_mass`). ``M_r u_r'' + K_r u_r = f_r`` is then a Hamiltonian system with
the energy ``E = 1/2 v_r^T M_r v_r + 1/2 u_r^T K_r u_r``, conserved exactly; central
differences conserve the modified energy ``1/2 v_(n+1/2)^T M_r v_(n+1/2) + 1/2 u_n^T K_r
u_(n+1)`` (Hughes 1987, "The Finite Element Method", ch. 9; positive, so stable) for steps
below ``2 / omega_max`` of ``M_r^-1 K_r``. Row-summing changes the mass of the interface
nodes only, by a consistent amount (the total mass and its first moments are unchanged).

*Consistency.* Linear fields ``u = A x + b`` are exact on both sides: a slave's GLL node
lies where the trilinear map puts it, which on an edge or face is the (bi)linear
interpolation of the corners' coordinates with the same weights, so the interpolated
value is ``A x_s + b`` (patch test, checked in ``tests/fem/test_spectral_mesh.py``).

In the time loop (:func:`prolongate` after each update, :func:`restrict` after each force
evaluation)::

    prolongate(u, ...)          # u_s = sum w u_m
    f = forces(u)               # K u on all nodes
    restrict(f, ...)            # f_m += w f_s; f_s = 0
    v += dt f / m_r             # on the free nodes (m_r of condense_mass)

Examples
--------
Two unit cubes side by side, the first promoted to order 2: its 27 nodes, 19 of them new;
the shared face's inner node and its 4 edges' inner nodes follow the order-1 neighbour:

>>> import numpy as np
>>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
>>> cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
...                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
>>> points = np.vstack([cube, cube[[1, 2, 5, 6]] + [1, 0, 0]])
>>> hexes = np.array([[0, 1, 2, 3, 4, 5, 6, 7], [1, 8, 9, 2, 5, 10, 11, 6]])
>>> sm = spectral_mesh(points, hexes, np.array([True, False]), 2)
>>> sm.elements.shape, sm.n_nodes, len(sm.slaves)
((1, 27), 31, 5)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .gll import check_order, gll_points
from .reference import HEX_CORNERS, element_batches, hex_shape_values

__all__ = [
    "HEX_FACES",
    "SpectralMesh",
    "condense_mass",
    "corner_positions",
    "prolongate",
    "restrict",
    "spectral_mesh",
]

#: The 6 faces of the hexahedron, corners in cyclic order (gmsh/VTK numbering).
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4],
                      [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
#: The 12 edges (corner pairs), as :data:`railvib_hpc.fem.reference.HEX_EDGES`.
HEX_EDGE_CORNERS = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                             [0, 4], [1, 5], [2, 6], [3, 7]])
#: Corners' GLL indices ``(i, j, k) / N`` (0 or 1 per reference axis).
_CORNER_UNIT = ((HEX_CORNERS + 1.0) / 2.0).astype(np.int64)


def corner_positions(order: int) -> np.ndarray:
    """The local (lexicographic) node of each of the 8 corners, gmsh/VTK order.

    >>> corner_positions(2).tolist()
    [0, 2, 8, 6, 18, 20, 26, 24]
    """
    n = check_order(order)
    ijk = _CORNER_UNIT * n
    return ijk[:, 0] + (n + 1) * ijk[:, 1] + (n + 1) ** 2 * ijk[:, 2]


@dataclass(frozen=True)
class SpectralMesh:
    """Spectral elements of order ``order`` on a hex8 mesh (:func:`spectral_mesh`).

    Attributes
    ----------
    order
        The polynomial order ``N``.
    points
        Coordinates of all nodes, shape (n_nodes, 3): the original ones first (unchanged),
        then the new GLL nodes.
    n_corner_nodes
        Number of original nodes (those of the hex8 mesh).
    elements
        Element-to-node map, shape (n_elements, (N + 1)^3), int64, lexicographic local order
        (module docstring).
    hex_ids
        The original hexahedron of each spectral element, shape (n_elements,).
    slaves
        Constrained nodes (on edges and faces shared with order-1 hexahedra), shape (ns,).
    masters
        Their master corners, shape (ns, 4) (edges: 2 masters, the last two columns repeat
        the first with weight 0).
    weights
        Interpolation weights, shape (ns, 4), each row summing to 1.
    """

    order: int
    points: np.ndarray
    n_corner_nodes: int
    elements: np.ndarray
    hex_ids: np.ndarray
    slaves: np.ndarray
    masters: np.ndarray
    weights: np.ndarray

    @property
    def n_nodes(self) -> int:
        """All nodes, original and new."""
        return len(self.points)

    @property
    def nbytes(self) -> int:
        """Memory of the arrays [B]."""
        return sum(a.nbytes for a in (self.points, self.elements, self.hex_ids, self.slaves,
                                      self.masters, self.weights))


def _local_ijk(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Per edge (12, N - 1) and per face (6, N - 1, N - 1) the local nodes of the inner
    points, in the element's own frame: edge ``(a, b)`` from ``a`` to ``b``; face
    ``(c0, c1, c2, c3)`` at ``c0 + s (c1 - c0) / N + t (c3 - c0) / N``, index ``[s - 1,
    t - 1]``."""
    n1 = n + 1
    stride = np.array([1, n1, n1 * n1])
    m = np.arange(1, n)
    corner = _CORNER_UNIT * n
    edges = np.stack([(corner[a] + np.outer(m, corner[b] - corner[a]) // n) @ stride
                      for a, b in HEX_EDGE_CORNERS])
    faces = []
    for c0, c1, _, c3 in HEX_FACES:
        du, dv = (corner[c1] - corner[c0]) // n, (corner[c3] - corner[c0]) // n
        ijk = corner[c0] + m[:, None, None] * du + m[None, :, None] * dv
        faces.append(ijk @ stride)
    return edges.reshape(12, n - 1), np.stack(faces).reshape(6, n - 1, n - 1)


def _unique_rows(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(unique rows, inverse)`` of an int64 key table (sorted, as ``np.unique``)."""
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)
    return uniq, inverse.reshape(-1)


def _face_frames(g: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Canonical frames of faces with corner ids ``g`` (nf, 4) in cyclic order: the origin's
    cycle position, the first axis's and the second axis's (each (nf,))."""
    o = np.argmin(g, axis=1)
    rows = np.arange(len(g))
    nxt, prv = (o + 1) % 4, (o + 3) % 4
    first_is_next = g[rows, nxt] < g[rows, prv]
    return o, np.where(first_is_next, nxt, prv), np.where(first_is_next, prv, nxt)


#: Face-frame coordinates (s, t) / N of the 4 cyclic corners.
_FACE_CORNER_ST = np.array([[0, 0], [1, 0], [1, 1], [0, 1]])


def _canonical_face_index(o, first, second, n: int) -> np.ndarray:
    """Per face occurrence (nf,), the canonical inner index ``(S - 1) + (N - 1)(T - 1)`` of
    the local inner point ``[s - 1, t - 1]``: shape (nf, N - 1, N - 1)."""
    m = np.arange(1, n)
    s, t = m[:, None], m[None, :]
    p0 = _FACE_CORNER_ST[o] * n                                     # (nf, 2)
    u = _FACE_CORNER_ST[first] - _FACE_CORNER_ST[o]
    v = _FACE_CORNER_ST[second] - _FACE_CORNER_ST[o]
    ds = s[None] - p0[:, 0, None, None]
    dt = t[None] - p0[:, 1, None, None]
    big_s = ds * u[:, 0, None, None] + dt * u[:, 1, None, None]
    big_t = ds * v[:, 0, None, None] + dt * v[:, 1, None, None]
    return (big_s - 1) + (n - 1) * (big_t - 1)


def spectral_mesh(points: ArrayLike, hexes: ArrayLike, promote: ArrayLike, order: int
                  ) -> SpectralMesh:
    """Promote the hexahedra ``hexes[promote]`` to spectral elements of order ``order``.

    Parameters
    ----------
    points
        Node coordinates of the hex8 mesh, shape (n_nodes, 3).
    hexes
        Hexahedra, shape (ne, 8), gmsh/VTK node order.
    promote
        Boolean mask (ne,) of the hexahedra to promote; the others stay trilinear and their
        shared edges and faces constrain the promoted side (module docstring).
    order
        ``N`` (1..8); 1 returns the promoted hexahedra unchanged (in lexicographic order).

    Returns
    -------
    SpectralMesh

    Examples
    --------
    One cube at order 3: 64 nodes, of which 56 new, no constraints:

    >>> import numpy as np
    >>> cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
    ...                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
    >>> sm = spectral_mesh(cube, np.arange(8)[None], [True], 3)
    >>> sm.n_nodes, len(sm.slaves), bool(np.allclose(sm.points[sm.elements[0, 1]],
    ...                                              [0.5 - 0.5 / 5 ** 0.5, 0, 0]))
    (64, 0, True)
    """
    n = check_order(order)
    points = np.asarray(points, dtype=float)
    hexes = np.asarray(hexes, dtype=np.int64)
    promote = np.asarray(promote, dtype=bool)
    if hexes.ndim != 2 or hexes.shape[1] != 8 or promote.shape != (len(hexes),):
        raise ValueError(f"hexes must be (ne, 8) and promote (ne,), got {hexes.shape} and "
                         f"{promote.shape}")
    n0 = len(points)
    ids = np.flatnonzero(promote)
    conn = hexes[ids]
    ne = len(ids)
    n1 = n + 1
    local = np.empty((ne, n1**3), dtype=np.int64)
    local[:, corner_positions(n)] = conn
    if n == 1 or ne == 0:
        return SpectralMesh(n, points.copy(), n0, local, ids, *_no_constraints())
    edge_local, face_local = _local_ijk(n)
    # --- edges: keyed by (smaller id, larger id) over all hexahedra
    g_edges = hexes[:, HEX_EDGE_CORNERS]                              # (ne_all, 12, 2)
    edge_keys, edge_of = _unique_rows(np.sort(g_edges, axis=2).reshape(-1, 2))
    edge_of = edge_of.reshape(len(hexes), 12)
    used_edges = np.unique(edge_of[ids])
    edge_number = np.full(len(edge_keys), -1, np.int64)
    edge_number[used_edges] = np.arange(len(used_edges))
    m = np.arange(1, n)
    forward = g_edges[ids, :, 0] < g_edges[ids, :, 1]                 # (ne, 12)
    pos = np.where(forward[..., None], m - 1, n - 1 - m)              # canonical index
    start = n0 + edge_number[edge_of[ids]][..., None] * (n - 1)
    local[np.arange(ne)[:, None, None], edge_local[None]] = start + pos
    # --- faces: keyed by the sorted 4 corner ids
    g_faces = hexes[:, HEX_FACES]                                      # (ne_all, 6, 4)
    face_keys, face_of = _unique_rows(np.sort(g_faces, axis=2).reshape(-1, 4))
    face_of = face_of.reshape(len(hexes), 6)
    used_faces = np.unique(face_of[ids])
    face_number = np.full(len(face_keys), -1, np.int64)
    face_number[used_faces] = np.arange(len(used_faces))
    first_face = n0 + len(used_edges) * (n - 1)
    gf = g_faces[ids].reshape(-1, 4)
    o, fa, fb = _face_frames(gf)
    canon = _canonical_face_index(o, fa, fb, n).reshape(ne, 6, n - 1, n - 1)
    start = first_face + face_number[face_of[ids]][..., None, None] * (n - 1) ** 2
    local[np.arange(ne)[:, None, None, None], face_local[None]] = start + canon
    # --- element interiors
    first_inner = first_face + len(used_faces) * (n - 1) ** 2
    inner = np.arange(1, n)
    kk, jj, ii = np.meshgrid(inner, inner, inner, indexing="ij")
    inner_local = (ii + n1 * jj + n1 * n1 * kk).ravel()
    local[:, inner_local] = (first_inner + np.arange(ne)[:, None] * (n - 1) ** 3
                             + np.arange((n - 1) ** 3)[None])
    n_total = first_inner + ne * (n - 1) ** 3
    new_points = np.empty((n_total, 3))
    new_points[:n0] = points
    _place_nodes(new_points, points, conn, local, n)
    slaves, masters, weights = _interface_constraints(
        n, hexes, promote, edge_keys, edge_of, edge_number, n0, face_keys, face_of,
        face_number, first_face)
    return SpectralMesh(n, new_points, n0, local, ids, slaves, masters, weights)


def _no_constraints() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return (np.zeros(0, np.int64), np.zeros((0, 4), np.int64), np.zeros((0, 4)))


def _place_nodes(out: np.ndarray, points: np.ndarray, conn: np.ndarray, local: np.ndarray,
                 n: int) -> None:
    """The GLL nodes' coordinates through each element's trilinear map (batched; a shared
    node is written by each of its elements, with the same value to round-off)."""
    x, _ = gll_points(n)
    n1 = n + 1
    a = np.arange(n1**3)
    ref = np.stack([x[a % n1], x[(a // n1) % n1], x[a // (n1 * n1)]], axis=1)
    shape = hex_shape_values(ref)                                       # (nq, 8)
    for s in element_batches(len(conn), max(1, 2**20 // n1**3)):
        out[local[s]] = np.einsum("qc,ecd->eqd", shape, points[conn[s]])


def _interface_constraints(n, hexes, promote, edge_keys, edge_of, edge_number, n0,
                           face_keys, face_of, face_number, first_face):
    """The slaves, masters and weights of the edges and faces shared between promoted and
    order-1 hexahedra."""
    x, _ = gll_points(n)
    inner = x[1:n]                                                     # (N - 1,)
    rest = ~promote

    def shared(of: np.ndarray, count: int) -> np.ndarray:
        a = np.zeros(count, bool)
        b = np.zeros(count, bool)
        a[of[promote].ravel()] = True
        b[of[rest].ravel()] = True
        return np.flatnonzero(a & b)

    parts = []
    edges = shared(edge_of, len(edge_keys))
    if edges.size:
        slaves = n0 + edge_number[edges][:, None] * (n - 1) + np.arange(n - 1)
        lo, hi = edge_keys[edges, 0][:, None], edge_keys[edges, 1][:, None]
        w_lo, w_hi = np.broadcast_to((1.0 - inner) / 2.0, slaves.shape), \
            np.broadcast_to((1.0 + inner) / 2.0, slaves.shape)
        lo, hi = np.broadcast_to(lo, slaves.shape), np.broadcast_to(hi, slaves.shape)
        masters = np.stack([lo, hi, lo, lo], axis=-1)
        weights = np.stack([w_lo, w_hi, np.zeros_like(w_lo), np.zeros_like(w_lo)], axis=-1)
        parts.append((slaves.ravel(), masters.reshape(-1, 4), weights.reshape(-1, 4)))
    faces = shared(face_of, len(face_keys))
    if faces.size:
        # the corners in cyclic order from any hexahedron that has the face
        flat = face_of.ravel()
        occurrence = np.empty(len(face_keys), np.int64)
        occurrence[flat] = np.arange(flat.size)
        g = hexes[:, HEX_FACES].reshape(-1, 4)[occurrence[faces]]
        o, fa, fb = _face_frames(g)
        rows = np.arange(len(g))
        opposite = (o + 2) % 4
        corners = np.stack([g[rows, o], g[rows, fa], g[rows, opposite], g[rows, fb]], axis=1)
        a, b = inner[:, None], inner[None, :]                          # [S - 1, T - 1]
        w = np.stack([(1 - a) * (1 - b), (1 + a) * (1 - b), (1 + a) * (1 + b),
                      (1 - a) * (1 + b)], axis=-1) / 4.0
        w = np.swapaxes(w, 0, 1).reshape(-1, 4)           # index (S - 1) + (N - 1)(T - 1)
        slaves = (first_face + face_number[faces][:, None] * (n - 1) ** 2
                  + np.arange((n - 1) ** 2))
        masters = np.broadcast_to(corners[:, None, :], slaves.shape + (4,))
        weights = np.broadcast_to(w[None], slaves.shape + (4,))
        parts.append((slaves.ravel(), masters.reshape(-1, 4), weights.reshape(-1, 4)))
    if not parts:
        return _no_constraints()
    return tuple(np.concatenate([p[i] for p in parts]) for i in range(3))


def prolongate(u: np.ndarray, slaves: np.ndarray, masters: np.ndarray, weights: np.ndarray
               ) -> np.ndarray:
    """``u[s] = sum_m w_sm u[m]`` for the constrained nodes (in place; ``u`` of shape
    (n_nodes,) or (n_nodes, 3)): the prolongation ``u = P u_r``.

    >>> u = np.array([0.0, 2.0, 5.0])
    >>> prolongate(u, np.array([2]), np.array([[0, 1, 0, 0]]), np.array([[0.25, 0.75, 0, 0]]))
    array([0. , 2. , 1.5])
    """
    if len(slaves):
        w = weights.reshape(weights.shape + (1,) * (u.ndim - 1))
        u[slaves] = (w * u[masters]).sum(axis=1)
    return u


def restrict(f: np.ndarray, slaves: np.ndarray, masters: np.ndarray, weights: np.ndarray
             ) -> np.ndarray:
    """``f[m] += w_sm f[s]``, then ``f[s] = 0`` (in place): the restriction ``P^T f`` of
    forces (or of a lumped mass, :func:`condense_mass`) onto the free nodes.

    >>> f = np.array([0.0, 0.0, 4.0])
    >>> restrict(f, np.array([2]), np.array([[0, 1, 0, 0]]), np.array([[0.25, 0.75, 0, 0]]))
    array([1., 3., 0.])
    """
    if len(slaves):
        w = weights.reshape(weights.shape + (1,) * (f.ndim - 1))
        part = w * f[slaves][:, None]
        if f.ndim == 1:
            np.add.at(f, masters.ravel(), part.ravel())
        else:
            np.add.at(f, masters.ravel(), part.reshape(-1, *f.shape[1:]))
        f[slaves] = 0.0
    return f


def condense_mass(mass: np.ndarray, slaves: np.ndarray, masters: np.ndarray,
                  weights: np.ndarray) -> np.ndarray:
    """The lumped mass of the reduced space, ``diag(P^T m)``: each slave's mass moved to
    its masters with its weights (row sums of ``P^T M P``, module docstring); the slaves'
    entries become 1 (they are not integrated: :func:`prolongate` sets them), a copy.

    >>> condense_mass(np.array([1.0, 1.0, 2.0]), np.array([2]), np.array([[0, 1, 0, 0]]),
    ...               np.array([[0.5, 0.5, 0, 0]])).tolist()
    [2.0, 2.0, 1.0]
    """
    m = restrict(np.array(mass, dtype=float), slaves, masters, weights)
    m[slaves] = 1.0
    return m
