"""The reference 8-node hexahedron and the element geometry built on it, in one place.

Everything that the finite-element kernels (:mod:`.hex8`), the mesh checks
(:mod:`railvib_hpc.mesh`) and the field reconstruction (:mod:`railvib_hpc.reconstruct`)
compute on the reference element lives here: corner coordinates, trilinear shape
functions and their reference gradients, the 2x2x2 Gauss rule, Jacobians, element
volumes and the physical shape-function gradients at the element centre.

Node order is gmsh/VTK: reference corners (-1,-1,-1), (1,-1,-1), (1,1,-1), (-1,1,-1),
(-1,-1,1), (1,-1,1), (1,1,1), (-1,1,1). Functions work on whole batches of elements,
``x`` of shape (nel, 8, 3), and never raise on degenerate or inverted elements: callers
decide (the kernels of :mod:`.hex8` raise :class:`ElementGeometryError`, the mesh quality
report counts them).

Examples
--------
>>> import numpy as np
>>> from railvib_hpc.fem.reference import HEX_CORNERS, hex_shape_values, hex_volumes
>>> bool(np.allclose(hex_shape_values(HEX_CORNERS), np.eye(8)))
True
>>> float(hex_volumes(2.0 * HEX_CORNERS[None])[0])    # a cube of edge 4
64.0
"""

from __future__ import annotations

import numpy as np

from .quadrature import gauss_hex

__all__ = [
    "GAUSS_POINTS",
    "GAUSS_WEIGHTS",
    "HEX_CORNERS",
    "HEX_CORNER_NEIGHBOURS",
    "HEX_EDGES",
    "ElementGeometryError",
    "element_batches",
    "hex_centre_gradients",
    "hex_centre_jacobians",
    "hex_corner_determinants",
    "hex_gauss_geometry",
    "hex_shape_gradients",
    "hex_shape_values",
    "hex_volumes",
]

#: Reference coordinates of the 8 corners (gmsh/VTK order), shape (8, 3).
HEX_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1],
                        [-1, -1, 1], [1, -1, 1], [1, 1, 1], [-1, 1, 1]], dtype=float)

#: For each corner, its three edge neighbours in right-handed order: the edge vectors to
#: them span a positive volume at every corner of a valid (VTK-ordered) hexahedron.
HEX_CORNER_NEIGHBOURS = np.array([[1, 3, 4], [2, 0, 5], [3, 1, 6], [0, 2, 7],
                                  [7, 5, 0], [4, 6, 1], [5, 7, 2], [6, 4, 3]])
#: The 12 edges of the hexahedron (corner pairs).
HEX_EDGES = np.array([[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4],
                      [0, 4], [1, 5], [2, 6], [3, 7]])
#: Elements per batch of the whole-mesh geometry checks (:func:`element_batches`): the
#: coordinates of a batch, (batch, 8, 3) float64, are 3.1 MB and each temporary of a corner
#: or edge loop 1.6 MB, so a check of any mesh size stays within a few tens of MB and in
#: cache (measured on 2.7 M hexahedra: 2**14 to 2**17 within 10 % of each other).
ELEMENT_BATCH = 2**14


def element_batches(n: int, size: int = ELEMENT_BATCH):
    """Slices ``[0:size], [size:2 size], ...`` covering ``range(n)``.

    >>> [(s.start, s.stop) for s in element_batches(5, 2)]
    [(0, 2), (2, 4), (4, 5)]
    """
    return (slice(k, min(k + size, n)) for k in range(0, n, size))


class ElementGeometryError(ValueError):
    """An element whose geometry the kernels cannot integrate (inverted or degenerate).

    A plain ``ValueError`` for the numerical layers; the stages turn it into a user error
    (:class:`railvib_hpc.errors.MeshError`) that names the mesh.
    """


def hex_shape_values(xi: np.ndarray) -> np.ndarray:
    """Trilinear shape functions at reference points.

    Parameters
    ----------
    xi
        Reference coordinates, shape (..., 3).

    Returns
    -------
    ndarray, shape (..., 8)
        ``N_a(xi) = prod_k (1 + xi_k xi_ak) / 8``.
    """
    xi = np.asarray(xi, dtype=float)
    return np.prod(1.0 + xi[..., None, :] * HEX_CORNERS, axis=-1) / 8.0


def hex_shape_gradients(xi: np.ndarray) -> np.ndarray:
    """Reference gradients of the 8 trilinear shape functions.

    Parameters
    ----------
    xi
        Reference coordinates, shape (q, 3) (or (3,) for one point).

    Returns
    -------
    ndarray, shape (q, 8, 3)
        ``dN_a / dxi_k``.
    """
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    f = 1.0 + xi[:, None, :] * HEX_CORNERS[None, :, :]          # (q, 8, 3)
    d = np.empty_like(f)
    d[..., 0] = HEX_CORNERS[:, 0] * f[..., 1] * f[..., 2]
    d[..., 1] = HEX_CORNERS[:, 1] * f[..., 0] * f[..., 2]
    d[..., 2] = HEX_CORNERS[:, 2] * f[..., 0] * f[..., 1]
    return d / 8.0


#: The 2x2x2 Gauss rule (exact for the volume and the mass of trilinear hexahedra):
#: points (8, 3), xi varying fastest, and weights (8,).
GAUSS_POINTS, GAUSS_WEIGHTS = gauss_hex(2)
#: Shape functions (8 points, 8 nodes) and their reference gradients (8 points, 8 nodes, 3)
#: at the Gauss points.
GAUSS_VALUES = hex_shape_values(GAUSS_POINTS)
GAUSS_GRADIENTS = hex_shape_gradients(GAUSS_POINTS)
_GAUSS_GRADIENTS_T = np.ascontiguousarray(GAUSS_GRADIENTS.transpose(0, 2, 1))   # (8, 3, 8)
#: Reference gradients at the centre ``xi = 0``, transposed: (3, 8).
_CENTRE_GRADIENTS_T = np.ascontiguousarray(hex_shape_gradients(np.zeros(3))[0].T)


def hex_gauss_geometry(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Physical shape-function gradients and Jacobian determinants at the Gauss points.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).

    Returns
    -------
    grad : ndarray, shape (nel, 8, 8, 3)
        ``grad[e, q, a, j] = dN_a / dx_j`` at Gauss point ``q`` (infinite or NaN where
        ``det`` is 0).
    det : ndarray, shape (nel, 8)
        Jacobian determinants (signed: <= 0 for inverted or degenerate elements).
    """
    J = np.matmul(_GAUSS_GRADIENTS_T[None], x[:, None])     # J[i, j] = dx_j / dxi_i
    adj = np.cross(J[..., [1, 2, 0], :], J[..., [2, 0, 1], :])        # rows: cofactor rows
    det = np.einsum("eqj,eqj->eq", J[..., 0, :], adj[..., 0, :])
    # J^-1 has the cofactor rows as columns, so grad_a = J^-1 dN_a = dN_a^T adj / det
    with np.errstate(divide="ignore", invalid="ignore"):
        grad = np.matmul(GAUSS_GRADIENTS[None], adj) / det[..., None, None]
    return grad, det


def hex_volumes(x: np.ndarray) -> np.ndarray:
    """Signed volumes of trilinear hexahedra (2x2x2 Gauss integration of det J: exact).

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).

    Returns
    -------
    ndarray, shape (nel,)
        Negative or zero for inverted or flat elements.
    """
    x = np.asarray(x, dtype=float)
    J = np.matmul(_GAUSS_GRADIENTS_T[None], x[:, None])
    return np.linalg.det(J) @ GAUSS_WEIGHTS


def hex_corner_determinants(x: np.ndarray, scaled: bool = False) -> np.ndarray:
    """Determinants of the three edge vectors leaving each corner (towards
    :data:`HEX_CORNER_NEIGHBOURS`), by the triple product; batched over elements.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).
    scaled
        Normalise the edge vectors first: the corner's *scaled Jacobian* (1 at a
        right-angled corner, <= 0 at an inverted one); a zero-length edge gives 0.

    Returns
    -------
    ndarray, shape (nel, 8)
        Positive at every corner of a valid element.

    Examples
    --------
    >>> import numpy as np
    >>> cube = (HEX_CORNERS + 1.0)[None]                   # edge 2
    >>> hex_corner_determinants(cube)[0].tolist() == [8.0] * 8
    True
    >>> float(hex_corner_determinants(cube[:, [4, 5, 6, 7, 0, 1, 2, 3]], True).min())
    -1.0
    """
    x = np.asarray(x, dtype=float)
    out = np.empty(x.shape[:1] + (8,))
    for k, nbr in enumerate(HEX_CORNER_NEIGHBOURS):     # a loop over the 8 corners
        a, b, c = (x[:, m] - x[:, k] for m in nbr)           # (nel, 3) each
        if scaled:
            a, b, c = (e / np.maximum(np.sqrt(np.einsum("ei,ei->e", e, e)), 1e-300)[:, None]
                       for e in (a, b, c))
        out[:, k] = (a[:, 0] * (b[:, 1] * c[:, 2] - b[:, 2] * c[:, 1])
                     + a[:, 1] * (b[:, 2] * c[:, 0] - b[:, 0] * c[:, 2])
                     + a[:, 2] * (b[:, 0] * c[:, 1] - b[:, 1] * c[:, 0]))
    return out


def hex_centre_jacobians(x: np.ndarray) -> np.ndarray:
    """Jacobians at the element centres.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).

    Returns
    -------
    ndarray, shape (nel, 3, 3)
        ``J0[e, i, j] = dx_j / dxi_i`` at ``xi = 0``.
    """
    return np.matmul(_CENTRE_GRADIENTS_T[None], np.asarray(x, dtype=float))


def hex_centre_gradients(x: np.ndarray) -> np.ndarray:
    """Physical shape-function gradients at the element centres.

    Parameters
    ----------
    x
        Nodal coordinates, shape (nel, 8, 3).

    Returns
    -------
    ndarray, shape (nel, 8, 3)
        ``g[e, a, j] = dN_a / dx_j`` at ``xi = 0``; exact for fields linear in x.

    Raises
    ------
    ElementGeometryError
        If a centre Jacobian is singular (a degenerate element).
    """
    J0 = hex_centre_jacobians(x)
    try:
        inv0 = np.linalg.inv(J0)                       # inv0[e, j, i] = dxi_i / dx_j
    except np.linalg.LinAlgError:
        raise ElementGeometryError("a hexahedron has a singular Jacobian at its centre "
                                   "(degenerate element)") from None
    return np.matmul(_CENTRE_GRADIENTS_T.T[None], inv0.transpose(0, 2, 1))
