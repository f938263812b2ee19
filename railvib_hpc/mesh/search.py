"""Point location in hexahedral meshes and face-conformity checks (vectorised).

``locate`` finds, for each query point, a hexahedron containing it and the
reference coordinates ``xi`` in [-1, 1]^3 (Newton inversion of the trilinear
map), so fields can be interpolated with the element shape functions.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..fem.reference import element_batches, hex_shape_gradients, hex_shape_values
from .model import Mesh

#: Newton steps of the inversion of the trilinear map: a fixed count keeps every candidate
#: of every point in one batch (quadratic convergence: ample for elements of the model).
NEWTON_STEPS = 12
#: Bound of the reference coordinates during the iteration: candidates that do not contain
#: the point move out of [-1, 1]^3 and are stopped here instead of diverging.
XI_BOUND = 3.0

#: Outward faces of a VTK-ordered hexahedron.
HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4],
                      [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
#: Margin of the bounding-box test of :func:`inside_any`, relative to each element's box:
#: a point the Newton inversion puts inside an element is in the convex hull of its corners
#: (to the round-off of the converged residual, ~1e-15 of its size), so within its box.
BOX_MARGIN = 1e-6


def locate(points: np.ndarray, mesh: Mesh, k: int = 12, tol: float = 1e-6
           ) -> tuple[np.ndarray, np.ndarray]:
    """Find a containing hex and reference coordinates for each point.

    Parameters
    ----------
    points
        Query points (m, 3).
    mesh
        The mesh.
    k
        Number of nearest element centroids tried per point.
    tol
        Tolerance on the reference coordinates (|xi| <= 1 + tol counts as inside).

    Returns
    -------
    elem : ndarray (m,)
        Index of a containing hex, -1 where none was found.
    xi : ndarray (m, 3)
        Reference coordinates in that hex (undefined where ``elem == -1``).
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    xe = mesh.points[mesh.hexes]                                  # (ne, 8, 3)
    tree = cKDTree(xe.mean(axis=1))
    k = min(k, len(xe))
    _, cand = tree.query(points, k=k)
    cand = cand.reshape(len(points), k)
    xi = _reference_coordinates(xe[cand], points)
    inside = np.all(np.abs(xi) <= 1.0 + tol, axis=-1)
    first = np.argmax(inside, axis=1)
    found = inside[np.arange(len(points)), first]
    elem = np.where(found, cand[np.arange(len(points)), first], -1)
    return elem, xi[np.arange(len(points)), first]


def _reference_coordinates(x: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Reference coordinates (m, k, 3) of ``points`` (m, 3) in each of the hexahedra
    ``x`` (m, k, 8, 3): :data:`NEWTON_STEPS` Newton steps from the centre, bounded by
    :data:`XI_BOUND`."""
    cand = x.shape[:2]
    xi = np.zeros(cand + (3,))
    for _ in range(NEWTON_STEPS):
        n = hex_shape_values(xi)                                  # (m, k, 8)
        dn = hex_shape_gradients(xi.reshape(-1, 3)).reshape(cand + (8, 3))
        r = np.einsum("mka,mkai->mki", n, x) - points[:, None, :]
        jac = np.einsum("mkai,mkaj->mkij", x, dn)
        det = np.linalg.det(jac)
        ok = np.abs(det) > 1e-300
        step = np.zeros_like(xi)
        step[ok] = np.linalg.solve(jac[ok], r[ok][..., None])[..., 0]
        xi = np.clip(xi - step, -XI_BOUND, XI_BOUND)
    return xi


def inside_any(points: np.ndarray, mesh: Mesh, k: int = 12, tol: float = 1e-6) -> np.ndarray:
    """Whether each point lies in a hexahedron: what ``locate(points, mesh, k, tol)[0] >= 0``
    says, without its (n_hexes, 8, 3) and (m, k, 8, 3) temporaries.

    The ``k`` candidates of a point are the same (the nearest element centres); only those
    whose bounding box holds the point (within :data:`BOX_MARGIN` of its size and ``tol``)
    are inverted, one element batch of boxes and one batch of pairs at a time. Points
    outside the box of the whole mesh have no candidate at all.
    """
    points = np.atleast_2d(np.asarray(points, dtype=float))
    found = np.zeros(len(points), dtype=bool)
    ne = len(mesh.hexes)
    if ne == 0 or len(points) == 0:
        return found
    centre, lo, hi = np.empty((ne, 3)), np.empty((ne, 3)), np.empty((ne, 3))
    for s in element_batches(ne):
        x = mesh.points[mesh.hexes[s].T]          # (8, batch, 3): reductions over whole rows
        centre[s], lo[s], hi[s] = x.mean(axis=0), x.min(axis=0), x.max(axis=0)
    margin = (BOX_MARGIN + max(tol, 0.0)) * (hi - lo).max(axis=1, keepdims=True)
    lo -= margin
    hi += margin
    near = np.flatnonzero(np.all((points >= lo.min(axis=0)) & (points <= hi.max(axis=0)),
                                 axis=1))
    if near.size == 0:
        return found
    k = min(k, ne)
    _, cand = cKDTree(centre).query(points[near], k=k)
    cand = cand.reshape(len(near), k)
    p = points[near][:, None, :]
    hit = np.all((p >= lo[cand]) & (p <= hi[cand]), axis=-1)         # (near, k)
    which, slot = np.nonzero(hit)
    for s in element_batches(len(which)):
        elem = cand[which[s], slot[s]]
        xi = _reference_coordinates(mesh.points[mesh.hexes[elem]][:, None],
                                    points[near[which[s]]])[:, 0]
        found[near[which[s]][np.all(np.abs(xi) <= 1.0 + tol, axis=-1)]] = True
    return found


def boundary_faces(hexes: np.ndarray) -> np.ndarray:
    """Faces (f, 4) that belong to exactly one hexahedron, outward oriented, in the order of
    the hexahedra and of their faces (:data:`HEX_FACES`).

    Two faces are the same when their sorted node numbers are: these four numbers are
    packed into two 64-bit keys (one element batch at a time) and sorted together, so no
    (6 n_hexes, 4) array is built or sorted row by row.
    """
    hexes = np.asarray(hexes)
    ne = len(hexes)
    if ne and (hexes.min() < 0 or hexes.max() >= 2**32):       # not packable: row-wise
        faces = hexes[:, HEX_FACES].reshape(-1, 4)
        _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True,
                                       return_counts=True)
        return faces[counts[inverse.ravel()] == 1]
    high, low = np.empty(6 * ne, dtype=np.uint64), np.empty(6 * ne, dtype=np.uint64)
    for s in element_batches(ne):
        f = hexes[s][:, HEX_FACES].reshape(-1, 4).astype(np.uint64)
        a, b, c, d = _sorted4(f[:, 0], f[:, 1], f[:, 2], f[:, 3])
        rows = slice(6 * s.start, 6 * s.stop)
        high[rows] = (a << np.uint64(32)) | b
        low[rows] = (c << np.uint64(32)) | d
    order = np.lexsort((low, high))
    high, low = high[order], low[order]
    same = (high[1:] == high[:-1]) & (low[1:] == low[:-1])           # face i+1 == face i
    alone = np.ones(6 * ne, dtype=bool)
    alone[1:] &= ~same
    alone[:-1] &= ~same
    face = np.sort(order[alone])
    return np.take_along_axis(hexes[face // 6], HEX_FACES[face % 6], axis=1)


def _sorted4(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray):
    """The four columns sorted row-wise (a sorting network of 5 compare-exchanges)."""
    a, b = np.minimum(a, b), np.maximum(a, b)
    c, d = np.minimum(c, d), np.maximum(c, d)
    a, c = np.minimum(a, c), np.maximum(a, c)
    b, d = np.minimum(b, d), np.maximum(b, d)
    b, c = np.minimum(b, c), np.maximum(b, c)
    return a, b, c, d


def nonconformal_faces(mesh: Mesh, exclude_nodes: np.ndarray | None = None) -> int:
    """Number of unshared hex faces that lie inside the meshed volume.

    In a conformal mesh every unshared face is on the outer surface, so a point
    just outside its centre is outside every element. A hanging node or a
    duplicated node on an interface leaves unshared faces whose outside
    neighbourhood is meshed; they are counted here, except faces whose four nodes are
    all ``exclude_nodes`` (the elastic interfaces, joined by springs by design).
    """
    faces = boundary_faces(mesh.hexes)
    if exclude_nodes is not None and len(exclude_nodes):
        skip = np.zeros(mesh.n_nodes, dtype=bool)
        skip[exclude_nodes] = True
        faces = faces[~skip[faces].all(axis=1)]
    p = mesh.points[faces]                                        # (f, 4, 3)
    centre = p.mean(axis=1)
    normal = np.cross(p[:, 2] - p[:, 0], p[:, 3] - p[:, 1])
    size = np.linalg.norm(normal, axis=1, keepdims=True)
    probe = centre + 1e-3 * np.sqrt(size) * normal / size
    return int(np.count_nonzero(inside_any(probe, mesh, k=8, tol=-1e-9)))
