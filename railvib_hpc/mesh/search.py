"""Point location in hexahedral meshes and face-conformity checks (vectorised).

``locate`` finds, for each query point, a hexahedron containing it and the
reference coordinates ``xi`` in [-1, 1]^3 (Newton inversion of the trilinear
map), so fields can be interpolated with the element shape functions.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..fem.reference import hex_shape_gradients, hex_shape_values
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
    x = xe[cand]                                                  # (m, k, 8, 3)
    xi = np.zeros(cand.shape + (3,))
    for _ in range(NEWTON_STEPS):
        n = hex_shape_values(xi)                                  # (m, k, 8)
        dn = hex_shape_gradients(xi.reshape(-1, 3)).reshape(cand.shape + (8, 3))
        r = np.einsum("mka,mkai->mki", n, x) - points[:, None, :]
        jac = np.einsum("mkai,mkaj->mkij", x, dn)
        det = np.linalg.det(jac)
        ok = np.abs(det) > 1e-300
        step = np.zeros_like(xi)
        step[ok] = np.linalg.solve(jac[ok], r[ok][..., None])[..., 0]
        xi = np.clip(xi - step, -XI_BOUND, XI_BOUND)
    inside = np.all(np.abs(xi) <= 1.0 + tol, axis=-1)
    first = np.argmax(inside, axis=1)
    found = inside[np.arange(len(points)), first]
    elem = np.where(found, cand[np.arange(len(points)), first], -1)
    return elem, xi[np.arange(len(points)), first]


def boundary_faces(hexes: np.ndarray) -> np.ndarray:
    """Faces (f, 4) that belong to exactly one hexahedron, outward oriented."""
    faces = hexes[:, HEX_FACES].reshape(-1, 4)
    key = np.sort(faces, axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    return faces[counts[inverse.ravel()] == 1]


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
    elem, _ = locate(probe, mesh, k=8, tol=-1e-9)
    return int((elem >= 0).sum())
