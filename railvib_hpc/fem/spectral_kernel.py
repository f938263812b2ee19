"""The elastic operator of spectral hexahedra: a sum-factorised, matrix-free ``f += K u``.

Isotropic linear elasticity (per element ``lambda``, ``mu``, ``rho``) on the spectral
hexahedra of :mod:`.spectral_mesh` (order ``N``, ``(N + 1)^3`` Gauss-Lobatto-Legendre nodes
per element in lexicographic order, the element's shape the trilinear map of its 8
corners), integrated with the GLL rule on the nodes themselves (Komatitsch & Tromp 1999,
"Introduction to the spectral element method for three-dimensional seismic wave
propagation", Geophys. J. Int. 139, 806-822). Per element and step:

1. gather ``u_e`` (``(N + 1)^3 x 3``);
2. the reference derivatives along ``xi``, ``eta``, ``zeta`` as three 1-D products with the
   differentiation matrix ``D`` of :mod:`.gll` (sum factorisation: ``3 (N + 1)^4`` multiply-adds
   per component instead of ``(N + 1)^6``);
3. at each GLL point the physical gradient, the stress ``lambda tr(eps) I + 2 mu eps`` and
   the flux ``w det J J^-1 sigma``;
4. the transposed 1-D products (``D^T``) give the nodal forces; scatter-add into ``f``.

**Geometry** (:func:`spectral_elasticity` chooses per element):

* *box* elements (axis-aligned, edges ``h_x, h_y, h_z``; the structured blocks of a site
  mesh): ``J^-1 = diag(2 / h)`` is constant, so the element holds a class number only, and
  the class table holds ``(2/h_x, 2/h_y, 2/h_z, lambda det J, mu det J)`` (classes where
  blocks repeat: one row per distinct size and material);
* *general* hexahedra (the shoulders): per GLL point the 9 numbers ``B = sqrt(w det J) J^-1``
  (``J^-1[i, j] = d xi_i / d x_j``, row-major ``3 i + j``); the gradient scaled by
  ``sqrt(w det J)`` gives the stress scaled alike, and ``B`` applied once more the flux
  ``w det J J^-1 sigma``, so no separate ``det J`` is stored.

**The lumped mass** is exact for GLL (the nodal quadrature of ``rho phi_a phi_b`` is
diagonal): ``m_a = sum_e rho_e w_a det J_e(x_a)``, one number per node (the three
components share it).

**Kernels.** :meth:`SpectralElasticity.add_forces` runs the compiled loop (Numba; one
specialisation per order and geometry, its loops of length ``N + 1`` unrolled and
vectorised by LLVM; ``fastmath`` lets it reassociate sums, which changes results at
round-off only); :func:`add_forces_array` is the same arithmetic as whole-array operations
(``einsum`` and ``bincount``, over chunks of elements) that a GPU array library with the
NumPy API (CuPy: pass ``xp=cupy`` and device arrays) runs unchanged. The two agree to
round-off (``tests/fem/test_spectral_kernel.py``).

**Local arrays and the MPI layer.** Everything here works on a rank's *local* arrays:
``elements`` numbers the nodes ``0 .. n_nodes - 1`` of the rank (owned and ghost nodes
alike), ``u`` and ``f`` are (n_nodes, 3) float64 C-contiguous arrays in that numbering.
A distributed operator wraps it as::

    u[ghosts] = values from their owners          # ghost gather (neighbour exchange)
    f[:] = -f_ext_local                           # or 0
    op.add_forces(u, f)                           # local elements only, f += K_local u
    send f[ghosts] to their owners, add there     # scatter-add (the reverse exchange)
    central_difference_update(u, v, f, inv_mass, dt)   # owned nodes

and builds the mass the same way once (``op.mass`` summed over the ranks that share a
node). No global numbering, no communicator and no PETSc object appears in this module.

**Cost** (``bench/spectral_bench.py``, one core): memory held per DOF is ``u, v, f`` and
the inverse mass (24 + 8 + 8 + 8 B if stored per component), the connectivity
(``4 (N + 1)^3 / (3 N^3)`` B, int32: 2.6 B at ``N = 4``) and the geometry (box: a class
number per element; general: ``72 (N + 1)^3 / (3 N^3)`` B, 47 B at ``N = 4``).

Examples
--------
A unit cube of order 2: a rigid translation has no force, the mass is ``rho V``:

>>> import numpy as np
>>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
>>> from railvib_hpc.fem.spectral_kernel import spectral_elasticity
>>> cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
...                  [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
>>> sm = spectral_mesh(cube, np.arange(8)[None], [True], 2)
>>> op = spectral_elasticity(2, sm.points, sm.elements, lam=1e8, mu=5e7, rho=2000.0)
>>> f = np.zeros((sm.n_nodes, 3))
>>> op.add_forces(np.tile([1.0, 0.0, 0.0], (sm.n_nodes, 1)), f)
>>> bool(np.abs(f).max() < 1e-6), round(float(op.mass.sum()), 9)
(True, 2000.0)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from .gll import check_order, derivative_matrix, gll_points, lexicographic_index
from .reference import ElementGeometryError, element_batches, hex_shape_gradients
from .spectral_mesh import corner_positions

try:
    import numba
except ImportError:                      # add_forces_array is the path without Numba
    numba = None

__all__ = [
    "BOX_TOLERANCE",
    "SpectralElasticity",
    "add_forces_array",
    "box_element_matrix",
    "central_difference_update",
    "element_matrices",
    "energy",
    "general_factors",
    "max_frequency_squared",
    "spectral_elasticity",
    "stiffness_diagonal",
]

#: An element is a box when every corner lies within this fraction of its largest edge of
#: the axis-aligned box of its extent (generated coordinates agree to ~1e-15 relative; the
#: same tolerance as the element classes of :mod:`.matrix_free`).
BOX_TOLERANCE = 1e-9
#: Number of columns of the box class table: ``2/h_x, 2/h_y, 2/h_z, lambda det J, mu det J``.
BOX_FACTORS = 5
#: Elements per chunk of the array kernel: bounds its temporaries (about 20 arrays of
#: ``(N + 1)^3 x 3`` doubles per element: ~30 MB at ``N = 4``).
ARRAY_CHUNK = 512
#: Power iterations of :func:`max_frequency_squared` by default, and the relative change of
#: the Rayleigh quotient between iterations at which it stops.
POWER_ITERATIONS, POWER_TOLERANCE = 200, 1e-6


def _reference_points(n: int) -> np.ndarray:
    """The GLL points of the hexahedron in the lexicographic local order, (nq, 3)."""
    x, _ = gll_points(n)
    ijk = lexicographic_index(n)
    return x[ijk]


def _point_weights(n: int) -> np.ndarray:
    """``w_i w_j w_k`` in the lexicographic local order, (nq,)."""
    _, w = gll_points(n)
    ijk = lexicographic_index(n)
    return w[ijk[:, 0]] * w[ijk[:, 1]] * w[ijk[:, 2]]


def _jacobians(n: int, x8: np.ndarray) -> np.ndarray:
    """``J[e, q, i, j] = d x_j / d xi_i`` of the trilinear map at the GLL points."""
    dn = hex_shape_gradients(_reference_points(n))                    # (nq, 8, 3)
    return np.einsum("qci,ecj->eqij", dn, x8)


def general_factors(order: int, x8: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    """Geometric factors of general hexahedra at their GLL points.

    Parameters
    ----------
    order
        ``N`` (1..8).
    x8
        Corner coordinates, shape (ne, 8, 3), gmsh/VTK order.

    Returns
    -------
    factors : ndarray, shape (ne, (N + 1)^3, 9)
        ``B = sqrt(w_q det J_q) J_q^-1`` row-major (``B[..., 3 i + j] ~ d xi_i / d x_j``).
    wdet : ndarray, shape (ne, (N + 1)^3)
        ``w_q det J_q`` (the volume each node carries).

    Raises
    ------
    ElementGeometryError
        If ``det J`` is not positive at some GLL point (an inverted or degenerate element).

    Examples
    --------
    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> b, wdet = general_factors(1, (2.0 * HEX_CORNERS)[None])      # a cube of edge 4
    >>> jinv = b[0, 0].reshape(3, 3) / np.sqrt(wdet[0, 0])            # d xi / d x = 1/2
    >>> round(float(wdet.sum()), 12), np.round(jinv, 12).tolist()[0]
    (64.0, [0.5, 0.0, 0.0])
    """
    n = check_order(order)
    x8 = np.asarray(x8, dtype=float)
    J = _jacobians(n, x8)
    det = np.linalg.det(J)
    bad = np.flatnonzero(np.any(~(det > 0.0), axis=1))
    if bad.size:
        raise ElementGeometryError(f"{bad.size} spectral hexahedra have a non-positive "
                                   f"Jacobian at a GLL point (first: element {bad[0]})")
    wdet = det * _point_weights(n)
    jinv = np.linalg.inv(J)                          # jinv[j, i] = d xi_i / d x_j
    factors = np.sqrt(wdet)[..., None, None] * np.swapaxes(jinv, -1, -2)
    return factors.reshape(x8.shape[0], -1, 9), wdet


def box_lengths(x8: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Which hexahedra are axis-aligned boxes (in the reference orientation: corner 1 along
    +x, 3 along +y, 4 along +z of corner 0), and their edges ``(h_x, h_y, h_z)``.

    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> ok, h = box_lengths(np.stack([HEX_CORNERS, HEX_CORNERS[[1, 2, 3, 0, 5, 6, 7, 4]]]))
    >>> ok.tolist(), h[0].tolist()
    ([True, False], [2.0, 2.0, 2.0])
    """
    unit = (np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float))
    h = x8[:, 6] - x8[:, 0]
    ideal = x8[:, :1] + unit[None] * h[:, None, :]
    scale = np.abs(h).max(axis=1)
    ok = (np.abs(x8 - ideal).max(axis=(1, 2)) <= BOX_TOLERANCE * scale) & np.all(h > 0, axis=1)
    return ok, h


@dataclass
class SpectralElasticity:
    """The elastic operator of spectral hexahedra on local arrays (:func:`spectral_elasticity`).

    Attributes
    ----------
    order
        ``N``.
    n_nodes
        Local nodes (the rows of ``u`` and ``f``).
    box_elements, box_class, box_table
        Box elements' nodes (nb, (N+1)^3) int32, their class (nb,) int32 and the class table
        (n_classes, 5): ``2/h_x, 2/h_y, 2/h_z, lambda det J, mu det J``.
    general_elements, general_factors, general_lame
        General elements' nodes (ng, (N+1)^3) int32, ``B = sqrt(w det J) J^-1`` in blocks of
        :data:`LANES` elements (ceil(ng / LANES), (N+1)^3, 9, LANES) (element ``e`` in block
        ``e // LANES``, lane ``e % LANES``; the last block's empty lanes 0) and ``(lambda,
        mu)`` (ng, 2).
    mass
        Lumped (diagonal, exact for GLL) nodal mass [kg], (n_nodes,).
    """

    order: int
    n_nodes: int
    box_elements: np.ndarray
    box_class: np.ndarray
    box_table: np.ndarray
    general_elements: np.ndarray
    general_factors: np.ndarray
    general_lame: np.ndarray
    mass: np.ndarray

    @property
    def n_elements(self) -> int:
        return len(self.box_elements) + len(self.general_elements)

    @property
    def nbytes(self) -> int:
        """Memory the operator holds [B] (connectivity, classes, geometry, mass)."""
        return sum(a.nbytes for a in (self.box_elements, self.box_class, self.box_table,
                                      self.general_elements, self.general_factors,
                                      self.general_lame, self.mass))

    def add_forces(self, u: np.ndarray, f: np.ndarray) -> None:
        """``f += K u`` by the compiled kernels (``u``, ``f``: (n_nodes, 3) float64,
        C-contiguous; without Numba, :func:`add_forces_array`)."""
        if numba is None:
            add_forces_array(self, u, f)
            return
        d = derivative_matrix(self.order)
        w = _point_weights(self.order)
        if len(self.box_elements):
            _compiled("box", self.order)(u, f, self.box_elements, self.box_class,
                                         self.box_table, _NO_FACTORS, _NO_LAME, d, w)
        if len(self.general_elements):
            _compiled("general", self.order)(u, f, self.general_elements, _NO_CLASS,
                                             _NO_TABLE, self.general_factors,
                                             self.general_lame, d, w)

    def forces(self, u: ArrayLike) -> np.ndarray:
        """``K u`` as a new (n_nodes, 3) array."""
        u = np.ascontiguousarray(np.asarray(u, dtype=float).reshape(self.n_nodes, 3))
        f = np.zeros_like(u)
        self.add_forces(u, f)
        return f


#: Placeholders of the kernels' unused arguments (one signature for both geometries).
_NO_CLASS, _NO_TABLE = np.zeros(1, np.int32), np.zeros((1, BOX_FACTORS))
_NO_FACTORS, _NO_LAME = np.zeros((1, 1, 9, 1)), np.zeros((1, 2))


def _per_element(value: ArrayLike, ne: int) -> np.ndarray:
    return np.broadcast_to(np.asarray(value, dtype=float), (ne,)).copy()


def spectral_elasticity(order: int, points: ArrayLike, elements: ArrayLike, lam: ArrayLike,
                        mu: ArrayLike, rho: ArrayLike, n_nodes: int | None = None,
                        geometry: str = "auto") -> SpectralElasticity:
    """Build the elastic operator of spectral hexahedra.

    Parameters
    ----------
    order
        ``N`` (1..8).
    points
        Local node coordinates, (n_nodes, 3) (only the corners are read: the element's
        shape is the trilinear map of its corners, as :func:`.spectral_mesh.spectral_mesh`
        places the GLL nodes).
    elements
        Element nodes, (ne, (N + 1)^3), lexicographic local order (:mod:`.spectral_mesh`).
    lam, mu, rho
        Lame parameters [Pa] and density [kg/m^3], scalars or one per element.
    n_nodes
        Local nodes (default ``len(points)``).
    geometry
        ``"auto"`` (boxes by class, the others general), ``"general"`` (all general:
        for tests and the benchmark) or ``"box"`` (all must be boxes).

    Returns
    -------
    SpectralElasticity

    Raises
    ------
    ValueError
        For a wrong shape or order, or ``geometry = "box"`` with a non-box element.
    ElementGeometryError
        For an inverted element.

    Examples
    --------
    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
    >>> sm = spectral_mesh(HEX_CORNERS, np.arange(8)[None], [True], 4)
    >>> op = spectral_elasticity(4, sm.points, sm.elements, 1.0, 1.0, 1.0)
    >>> len(op.box_elements), len(op.general_elements), round(float(op.mass.sum()), 12)
    (1, 0, 8.0)
    """
    n = check_order(order)
    points = np.asarray(points, dtype=float)
    elements = np.asarray(elements)
    nq = (n + 1) ** 3
    if elements.ndim != 2 or elements.shape[1] != nq:
        raise ValueError(f"elements of order {n} must have shape (ne, {nq}), got "
                         f"{elements.shape}")
    if geometry not in ("auto", "general", "box"):
        raise ValueError(f"geometry must be 'auto', 'general' or 'box', got {geometry!r}")
    ne = len(elements)
    n_nodes = len(points) if n_nodes is None else int(n_nodes)
    lam, mu, rho = (_per_element(v, ne) for v in (lam, mu, rho))
    x8 = points[elements[:, corner_positions(n)]]
    is_box, h = box_lengths(x8)
    if geometry == "general":
        is_box[:] = False
    elif geometry == "box" and not is_box.all():
        raise ValueError(f"{np.count_nonzero(~is_box)} elements are not axis-aligned boxes "
                         f"(first: {np.flatnonzero(~is_box)[0]})")
    conn = elements.astype(np.int32)
    mass = np.zeros(n_nodes)
    box = np.flatnonzero(is_box)
    det = np.prod(h[box], axis=1) / 8.0
    table = np.column_stack([2.0 / h[box], lam[box] * det, mu[box] * det])
    if len(box):
        key = np.round(np.log(np.abs(table) + 1e-300) / BOX_TOLERANCE).astype(np.int64)
        _, first, box_class = np.unique(key, axis=0, return_index=True, return_inverse=True)
    else:
        first, box_class = np.zeros(0, np.int64), np.zeros(0, np.int64)
    w = _point_weights(n)
    np.add.at(mass, conn[box].ravel(), ((rho[box] * det)[:, None] * w[None]).ravel())
    gen = np.flatnonzero(~is_box)
    factors = np.zeros(((len(gen) + LANES - 1) // LANES, nq, 9, LANES))
    for s in element_batches(len(gen), max(1, 2**18 // nq)):
        ids = np.arange(s.start, s.stop)
        factors[ids // LANES, :, :, ids % LANES], wdet = general_factors(n, x8[gen[s]])
        np.add.at(mass, conn[gen[s]].ravel(), (rho[gen[s], None] * wdet).ravel())
    return SpectralElasticity(
        order=n, n_nodes=n_nodes, box_elements=np.ascontiguousarray(conn[box]),
        box_class=box_class.reshape(-1).astype(np.int32),
        box_table=np.ascontiguousarray(table[first]),
        general_elements=np.ascontiguousarray(conn[gen]), general_factors=factors,
        general_lame=np.column_stack([lam[gen], mu[gen]]), mass=mass)


# ----------------------------------------------------------------------------- compiled

#: Elements per SIMD block of the compiled kernels: the innermost loop of every stage runs
#: over the block's elements (one element per lane), which LLVM vectorises for any order.
#: Measured on this machine (AMD EPYC, AVX-512), ``N = 4`` box kernel: 4 or 8 lanes 21-22
#: ns per DOF (not vectorised), 16 lanes 8.1-8.4, 24 6.8, 32 7.9, 64 8.8; ``N = 8``: 16
#: and 32 lanes 8.6-9.0. 16 is a multiple of every x86 vector width (AVX2 too).
LANES = 16

_KERNELS: dict[tuple[str, int], object] = {}


def _compiled(kind: str, order: int):
    """The Numba kernel of ``kind`` (``"box"``, ``"general"``) for ``order``, compiled once
    per process (and cached on disk) with ``N + 1`` and :data:`LANES` compile-time
    constants."""
    key = (kind, order)
    if key not in _KERNELS:
        _KERNELS[key] = _make_kernel(kind, order + 1)
    return _KERNELS[key]


def _make_kernel(kind: str, n1: int):
    """``f += K u`` over box or general elements, in blocks of :data:`LANES` elements
    (``n1 = N + 1`` and the lanes frozen into the compiled code). The last block's empty
    lanes repeat its last element and are not scattered."""
    lanes = LANES
    box = kind == "box"

    @numba.njit(cache=True, fastmath=True)
    def kernel(u, f, conn, cls, table, factors, lame, d, w):   # pragma: no cover (compiled)
        ue = np.empty((3, n1, n1, n1, lanes))
        g = np.empty((9, n1, n1, n1, lanes))
        coef = np.empty((5, lanes))
        w3 = w.reshape(n1, n1, n1)
        ne = conn.shape[0]
        for block in range((ne + lanes - 1) // lanes):
            e0 = block * lanes
            used = min(lanes, ne - e0)
            for lane in range(lanes):
                e = e0 + min(lane, used - 1)
                if box:
                    c = cls[e]
                    for m in range(5):
                        coef[m, lane] = table[c, m]
                else:
                    coef[3, lane] = lame[e, 0]
                    coef[4, lane] = lame[e, 1]
                for k in range(n1):
                    for j in range(n1):
                        for i in range(n1):
                            node = conn[e, i + n1 * (j + n1 * k)]
                            ue[0, k, j, i, lane] = u[node, 0]
                            ue[1, k, j, i, lane] = u[node, 1]
                            ue[2, k, j, i, lane] = u[node, 2]
            # reference gradients g[3 c + r] = d u_c / d xi_r (three 1-D products with D)
            for c in range(3):
                for k in range(n1):
                    for j in range(n1):
                        for i in range(n1):
                            for lane in range(lanes):
                                s0 = 0.0
                                s1 = 0.0
                                s2 = 0.0
                                for p in range(n1):
                                    s0 += d[i, p] * ue[c, k, j, p, lane]
                                    s1 += d[j, p] * ue[c, k, p, i, lane]
                                    s2 += d[k, p] * ue[c, p, j, i, lane]
                                g[3 * c, k, j, i, lane] = s0
                                g[3 * c + 1, k, j, i, lane] = s1
                                g[3 * c + 2, k, j, i, lane] = s2
            for k in range(n1):
                for j in range(n1):
                    for i in range(n1):
                        if box:
                            _box_points(g, coef, w3[k, j, i], k, j, i, lanes)
                        else:
                            _general_points(g, factors[block, i + n1 * (j + n1 * k)], coef,
                                            k, j, i, lanes)
            # nodal forces: the transposed products, into ue
            for c in range(3):
                for k in range(n1):
                    for j in range(n1):
                        for i in range(n1):
                            for lane in range(lanes):
                                s = 0.0
                                for p in range(n1):
                                    s += (d[p, i] * g[3 * c, k, j, p, lane]
                                          + d[p, j] * g[3 * c + 1, k, p, i, lane]
                                          + d[p, k] * g[3 * c + 2, p, j, i, lane])
                                ue[c, k, j, i, lane] = s
            for lane in range(used):
                e = e0 + lane
                for k in range(n1):
                    for j in range(n1):
                        for i in range(n1):
                            node = conn[e, i + n1 * (j + n1 * k)]
                            f[node, 0] += ue[0, k, j, i, lane]
                            f[node, 1] += ue[1, k, j, i, lane]
                            f[node, 2] += ue[2, k, j, i, lane]

    return kernel


def _jit(function):
    """``numba.njit(cache=True, fastmath=True)``, or the plain function without Numba."""
    return function if numba is None else numba.njit(cache=True, fastmath=True)(function)


@_jit
def _box_points(g, coef, wq, k, j, i, lanes):     # pragma: no cover (compiled)
    """Box elements at point ``(k, j, i)`` of every lane: ``g`` (reference gradients
    ``d u_c / d xi_r`` at ``[3 c + r]``) becomes the flux ``w det J (2 / h_r) sigma_cr``
    (``coef``: ``2/h_x, 2/h_y, 2/h_z, lambda det J, mu det J`` per lane)."""
    for lane in range(lanes):
        ax, ay, az = coef[0, lane], coef[1, lane], coef[2, lane]
        lam, mu = coef[3, lane], coef[4, lane]
        exx = ax * g[0, k, j, i, lane]
        eyy = ay * g[4, k, j, i, lane]
        ezz = az * g[8, k, j, i, lane]
        tr = lam * (exx + eyy + ezz)
        sxy = mu * (ay * g[1, k, j, i, lane] + ax * g[3, k, j, i, lane])
        sxz = mu * (az * g[2, k, j, i, lane] + ax * g[6, k, j, i, lane])
        syz = mu * (az * g[5, k, j, i, lane] + ay * g[7, k, j, i, lane])
        sxx = tr + 2.0 * mu * exx
        syy = tr + 2.0 * mu * eyy
        szz = tr + 2.0 * mu * ezz
        wx, wy, wz = wq * ax, wq * ay, wq * az
        g[0, k, j, i, lane] = wx * sxx
        g[1, k, j, i, lane] = wy * sxy
        g[2, k, j, i, lane] = wz * sxz
        g[3, k, j, i, lane] = wx * sxy
        g[4, k, j, i, lane] = wy * syy
        g[5, k, j, i, lane] = wz * syz
        g[6, k, j, i, lane] = wx * sxz
        g[7, k, j, i, lane] = wy * syz
        g[8, k, j, i, lane] = wz * szz


@_jit
def _general_points(g, b, coef, k, j, i, lanes):    # pragma: no cover (compiled)
    """General elements at point ``(k, j, i)`` of every lane: the scaled gradient
    ``G[c, s] = sum_r B[r, s] g[3 c + r]``, its stress, and the flux ``sum_s B[r, s]
    sigma[c, s]`` into ``g`` (``b``: (9, lanes), ``B[3 r + s]``; ``coef[3:5]``: lambda, mu)."""
    for lane in range(lanes):
        lam, mu = coef[3, lane], coef[4, lane]
        b0, b1, b2 = b[0, lane], b[1, lane], b[2, lane]
        b3, b4, b5 = b[3, lane], b[4, lane], b[5, lane]
        b6, b7, b8 = b[6, lane], b[7, lane], b[8, lane]
        r0, r1, r2 = g[0, k, j, i, lane], g[1, k, j, i, lane], g[2, k, j, i, lane]
        gxx, gxy, gxz = b0 * r0 + b3 * r1 + b6 * r2, b1 * r0 + b4 * r1 + b7 * r2, \
            b2 * r0 + b5 * r1 + b8 * r2
        r0, r1, r2 = g[3, k, j, i, lane], g[4, k, j, i, lane], g[5, k, j, i, lane]
        gyx, gyy, gyz = b0 * r0 + b3 * r1 + b6 * r2, b1 * r0 + b4 * r1 + b7 * r2, \
            b2 * r0 + b5 * r1 + b8 * r2
        r0, r1, r2 = g[6, k, j, i, lane], g[7, k, j, i, lane], g[8, k, j, i, lane]
        gzx, gzy, gzz = b0 * r0 + b3 * r1 + b6 * r2, b1 * r0 + b4 * r1 + b7 * r2, \
            b2 * r0 + b5 * r1 + b8 * r2
        tr = lam * (gxx + gyy + gzz)
        sxx, syy, szz = tr + 2.0 * mu * gxx, tr + 2.0 * mu * gyy, tr + 2.0 * mu * gzz
        sxy, sxz, syz = mu * (gxy + gyx), mu * (gxz + gzx), mu * (gyz + gzy)
        g[0, k, j, i, lane] = b0 * sxx + b1 * sxy + b2 * sxz
        g[1, k, j, i, lane] = b3 * sxx + b4 * sxy + b5 * sxz
        g[2, k, j, i, lane] = b6 * sxx + b7 * sxy + b8 * sxz
        g[3, k, j, i, lane] = b0 * sxy + b1 * syy + b2 * syz
        g[4, k, j, i, lane] = b3 * sxy + b4 * syy + b5 * syz
        g[5, k, j, i, lane] = b6 * sxy + b7 * syy + b8 * syz
        g[6, k, j, i, lane] = b0 * sxz + b1 * syz + b2 * szz
        g[7, k, j, i, lane] = b3 * sxz + b4 * syz + b5 * szz
        g[8, k, j, i, lane] = b6 * sxz + b7 * syz + b8 * szz


@_jit
def _central_difference(u, v, f, inv_mass, dt):    # pragma: no cover (compiled)
    n = u.shape[0]
    for a in range(n):
        for c in range(3):
            v[a, c] -= dt * inv_mass[a, c] * f[a, c]
            u[a, c] += dt * v[a, c]
            f[a, c] = 0.0


def central_difference_update(u: np.ndarray, v: np.ndarray, f: np.ndarray,
                              inv_mass: np.ndarray, dt: float) -> None:
    """One central-difference (leapfrog) update, in place and fused in one pass:
    ``v -= dt inv_mass f``, ``u += dt v``, ``f = 0`` (ready for the next ``f = K u -
    f_ext``).

    ``v`` is the velocity at the half steps (``v_(n+1/2)``), ``f = K u_n - f_ext,n``;
    ``inv_mass`` (n_nodes, 3) holds ``1 / m`` per component, 0 where a component is held
    (rollers, fixed nodes, constrained slaves). All arrays (n_nodes, 3) float64.

    Examples
    --------
    >>> u, v, f = np.zeros((1, 3)), np.zeros((1, 3)), np.array([[-2.0, 0.0, 0.0]])
    >>> central_difference_update(u, v, f, np.full((1, 3), 0.5), 0.1)
    >>> u.tolist(), v.tolist(), f.tolist()
    ([[0.010000000000000002, 0.0, 0.0]], [[0.1, 0.0, 0.0]], [[0.0, 0.0, 0.0]])
    """
    _central_difference(u, v, f, inv_mass, float(dt))


# ----------------------------------------------------------------------------- arrays

def _array_reference_gradient(xp, ue, d):
    """``dref[e, k, j, i, r, c] = d u_c / d xi_r`` of ``ue`` (e, k, j, i, c)."""
    return xp.stack([xp.einsum("ip,ekjpc->ekjic", d, ue), xp.einsum("jp,ekpic->ekjic", d, ue),
                     xp.einsum("kp,epjic->ekjic", d, ue)], axis=4)


def _array_transposed(xp, flux, d):
    """``sum_r D_r^T flux[..., r, c]``, (e, k, j, i, c)."""
    return (xp.einsum("pi,ekjpc->ekjic", d, flux[:, :, :, :, 0])
            + xp.einsum("pj,ekpic->ekjic", d, flux[:, :, :, :, 1])
            + xp.einsum("pk,epjic->ekjic", d, flux[:, :, :, :, 2]))


def _array_stress(xp, grad, lam, mu):
    """``lam tr(grad) I + mu (grad + grad^T)`` of ``grad[..., c, s]``; ``lam``, ``mu``
    broadcast over the leading axes."""
    tr = xp.einsum("...cc->...", grad)
    return (lam[..., None, None] * tr[..., None, None] * xp.eye(3)
            + mu[..., None, None] * (grad + xp.swapaxes(grad, -1, -2)))


def _factors_of(op: SpectralElasticity, select) -> np.ndarray:
    """The general elements' ``B`` of ``select`` (a slice or indices), (ne, (N+1)^3, 9), from
    the blocked layout of the compiled kernel."""
    ids = np.arange(len(op.general_elements))[select]
    return op.general_factors[ids // LANES, :, :, ids % LANES]


def element_forces_array(op: SpectralElasticity, kind: str, ue, select=slice(None), xp=np):
    """The element forces ``K_e u_e`` of elements ``select`` of ``kind`` (``"box"`` or
    ``"general"``) for element displacements ``ue`` (ne, (N+1)^3, 3): whole-array
    operations only (:func:`add_forces_array`)."""
    n1 = op.order + 1
    d = xp.asarray(derivative_matrix(op.order))
    ue = ue.reshape(-1, n1, n1, n1, 3)
    dref = _array_reference_gradient(xp, ue, d)                   # (e, k, j, i, r, c)
    if kind == "box":
        row = xp.asarray(op.box_table)[xp.asarray(op.box_class[select])]   # (e, 5)
        a = row[:, :3]
        grad = dref.swapaxes(-1, -2) * a[:, None, None, None, None, :]   # [c, s] = a_s dref
        sigma = _array_stress(xp, grad, row[:, None, None, None, 3], row[:, None, None, None, 4])
        w = xp.asarray(_point_weights(op.order)).reshape(1, n1, n1, n1, 1, 1)
        flux = (w * a[:, None, None, None, :, None]) * sigma.swapaxes(-1, -2)   # [r, c]
    else:
        b = xp.asarray(_factors_of(op, select)).reshape(-1, n1, n1, n1, 3, 3)
        lame = xp.asarray(op.general_lame[select])
        grad = xp.einsum("ekjirs,ekjirc->ekjics", b, dref)
        sigma = _array_stress(xp, grad, lame[:, None, None, None, 0], lame[:, None, None, None, 1])
        flux = xp.einsum("ekjirs,ekjics->ekjirc", b, sigma)
    return _array_transposed(xp, flux, d).reshape(-1, n1**3, 3)


def add_forces_array(op: SpectralElasticity, u, f, xp=np) -> None:
    """``f += K u`` with whole-array operations (``einsum``, ``bincount``) over chunks of
    :data:`ARRAY_CHUNK` elements: the reference of the compiled kernel, and the form a GPU
    array library with the NumPy API runs unchanged (``xp=cupy``, ``u`` and ``f`` device
    arrays (n_nodes, 3)).

    Examples
    --------
    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
    >>> sm = spectral_mesh(HEX_CORNERS, np.arange(8)[None], [True], 3)
    >>> op = spectral_elasticity(3, sm.points, sm.elements, 2.0, 1.0, 1.0)
    >>> u = np.random.default_rng(0).standard_normal((sm.n_nodes, 3))
    >>> f1, f2 = op.forces(u), np.zeros_like(u)
    >>> add_forces_array(op, u, f2)
    >>> bool(np.abs(f1 - f2).max() < 1e-12 * np.abs(f1).max())
    True
    """
    size = 3 * op.n_nodes
    for kind, conn in (("box", op.box_elements), ("general", op.general_elements)):
        for s in element_batches(len(conn), ARRAY_CHUNK):
            c = xp.asarray(conn[s]).astype(xp.int64)
            fe = element_forces_array(op, kind, u[c], s, xp)
            index = (3 * c[..., None] + xp.arange(3)).ravel()
            f += xp.bincount(index, weights=fe.ravel(), minlength=size).reshape(-1, 3)


# ----------------------------------------------------------------------------- helpers

def element_matrices(op: SpectralElasticity, kind: str = "box", select=slice(None)
                     ) -> np.ndarray:
    """Element stiffness matrices by the array kernel applied to unit vectors.

    Returns
    -------
    ndarray, shape (ne, 3 (N+1)^3, 3 (N+1)^3)
        Node-major DOF order ``3 a + c`` (``a`` lexicographic); symmetric.

    Examples
    --------
    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
    >>> sm = spectral_mesh(HEX_CORNERS, np.arange(8)[None], [True], 2)
    >>> k = element_matrices(spectral_elasticity(2, sm.points, sm.elements, 1.0, 1.0, 1.0))
    >>> k.shape, int(np.sum(np.linalg.eigvalsh(k[0]) < 1e-10))   # 6 rigid-body modes
    ((1, 81, 81), 6)
    """
    conn = op.box_elements if kind == "box" else op.general_elements
    ids = np.arange(len(conn))[select]
    ndof = 3 * (op.order + 1) ** 3
    eye = np.eye(ndof).reshape(ndof, -1, 3)
    out = np.empty((len(ids), ndof, ndof))
    for m, e in enumerate(ids):
        fe = element_forces_array(op, kind, eye, np.full(ndof, e))
        out[m] = fe.reshape(ndof, ndof)                 # row: unit vector; K symmetric
    return out


def box_element_matrix(order: int, h: ArrayLike, lam: float, mu: float) -> np.ndarray:
    """The stiffness of one box element from 1-D GLL matrices (the tensor construction).

    With the 1-D mass ``M1 = W h / 2``, stiffness ``K1 = D^T W D (2 / h)`` and mixed matrix
    ``C1 = W D`` (``W = diag(w)``), the integrals ``S_cd[a, b] = int d_c phi_a d_d phi_b``
    are Kronecker products: ``S_cc`` has ``K1`` along ``c`` and ``M1`` along the other two
    axes, ``S_cd`` (``c != d``) ``C1^T`` along ``c``, ``C1`` along ``d`` and ``M1`` along the
    third (the lexicographic order makes ``kron(Z, kron(Y, X))``). Then
    ``K[(a, c), (b, d)] = lambda S_cd + mu S_dc + mu delta_cd sum_m S_mm``. Independent of
    the sum-factorised kernel (the tests compare the two), and the element of the Bloch
    analyses (:mod:`.dispersion_gll`).

    Parameters
    ----------
    order
        ``N`` (1..8).
    h
        Edges ``(h_x, h_y, h_z)`` (or one for a cube).
    lam, mu
        Lame parameters.

    Returns
    -------
    ndarray, shape (3 (N+1)^3, 3 (N+1)^3)
        Node-major DOF order ``3 a + c``, lexicographic ``a``.

    Examples
    --------
    The 1-D two-node element ``[[1, -1], [-1, 1]] / h`` is the ``N = 1`` ``K1``; a cube of
    order 1 has the 6 rigid-body modes and 18 positive ones:

    >>> k = box_element_matrix(1, 2.0, 1.0, 1.0)
    >>> k.shape, int(np.sum(np.abs(np.linalg.eigvalsh(k)) < 1e-12))
    ((24, 24), 6)
    """
    n = check_order(order)
    h = np.broadcast_to(np.asarray(h, dtype=float), (3,))
    _, w = gll_points(n)
    d = derivative_matrix(n)
    m1 = [np.diag(w) * hc / 2.0 for hc in h]
    k1 = [d.T @ np.diag(w) @ d * (2.0 / hc) for hc in h]
    c1 = np.diag(w) @ d

    def kron3(mats):                                # mats along (x, y, z)
        return np.kron(mats[2], np.kron(mats[1], mats[0]))

    nq = (n + 1) ** 3
    s = np.empty((3, 3, nq, nq))
    for c in range(3):
        for dd in range(3):
            mats = list(m1)
            if c == dd:
                mats[c] = k1[c]
            else:
                mats[c], mats[dd] = c1.T, c1
            s[c, dd] = kron3(mats)
    k = np.empty((nq, 3, nq, 3))
    trace = s[0, 0] + s[1, 1] + s[2, 2]
    for c in range(3):
        for dd in range(3):
            k[:, c, :, dd] = lam * s[c, dd] + mu * s[dd, c] + (mu * trace if c == dd else 0.0)
    return k.reshape(3 * nq, 3 * nq)


def _cross_reference_gradients(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The nonzero reference gradients of the basis: for node ``a`` and the ``3 (N + 1)``
    points on the three GLL lines through it, the point's local index (nq, 3 n1) and
    ``d phi_a / d xi`` there (nq, 3 n1, 3); the node itself counted once (on its ``xi``
    line, with its full gradient), the other two lines' copies with zero gradient."""
    n1 = n + 1
    d = derivative_matrix(n)
    ijk = lexicographic_index(n)
    p = np.arange(n1)
    stride = np.array([1, n1, n1 * n1])
    points = np.empty((n1**3, 3, n1), np.int64)
    grads = np.zeros((n1**3, 3, n1, 3))
    for r in range(3):
        q = np.repeat(ijk[:, None, :], n1, axis=1)
        q[:, :, r] = p
        points[:, r] = q @ stride
        own = ijk[:, r][:, None]
        # along line r: d/dxi_r of l_(own) at p; the other derivatives vanish off the node
        grads[:, r, :, r] = d[p[None, :], own]
        if r == 0:
            for s in (1, 2):
                grads[:, 0, :, s] = np.where(p[None, :] == own, d[ijk[:, s], ijk[:, s]][:, None],
                                             0.0)
        else:
            grads[:, r] = np.where((p[None, :] == own)[..., None], 0.0, grads[:, r])
    return points.reshape(n1**3, -1), grads.reshape(n1**3, -1, 3)


def stiffness_diagonal(op: SpectralElasticity) -> np.ndarray:
    """The diagonal of ``K``, (n_nodes, 3): per element and node ``sum_q w det J (mu |grad
    phi_a|^2 + (lambda + mu) (d phi_a / d x_c)^2)`` over the ``3 N + 1`` points where the
    node's basis function has a gradient (batched; for Jacobi preconditioning and
    stability estimates).

    Examples
    --------
    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
    >>> sm = spectral_mesh(HEX_CORNERS, np.arange(8)[None], [True], 2)
    >>> op = spectral_elasticity(2, sm.points, sm.elements, 2.0, 1.0, 1.0)
    >>> k = element_matrices(op)[0]                   # in the element's local order
    >>> local = stiffness_diagonal(op)[sm.elements[0]]
    >>> bool(np.allclose(local.ravel(), np.diag(k)))
    True
    """
    n = op.order
    n1 = n + 1
    points, gref = _cross_reference_gradients(n)                    # (nq, m), (nq, m, 3)
    out = np.zeros((op.n_nodes, 3))
    w = _point_weights(n)
    for s in element_batches(len(op.box_elements), max(1, 2**16 // n1**3)):
        row = op.box_table[op.box_class[s]]
        g = gref[None] * row[:, None, None, :3]                      # d phi / d x
        wq = w[points][None]                                         # (1, nq, m)
        _add_diagonal(out, op.box_elements[s], g, wq, row[:, 3], row[:, 4], unit=True)
    for s in element_batches(len(op.general_elements), max(1, 2**16 // n1**3)):
        b = _factors_of(op, s).reshape(-1, n1**3, 3, 3)[:, points]  # (e, nq, m, 3, 3)
        g = np.einsum("eamrs,amr->eams", b, gref)                   # sqrt(w det) grad
        lame = op.general_lame[s]
        _add_diagonal(out, op.general_elements[s], g, 1.0, lame[:, 0], lame[:, 1], unit=False)
    return out


def _add_diagonal(out, conn, g, wq, lam, mu, unit: bool) -> None:
    """Accumulate ``sum_q wq (mu |g|^2 + (lam + mu) g_c^2)`` per element node."""
    g2 = g * g * (wq[..., None] if unit else 1.0)
    total = g2.sum(axis=-1, keepdims=True)
    de = (mu[:, None, None, None] * total + (lam + mu)[:, None, None, None] * g2).sum(axis=2)
    np.add.at(out, conn.ravel(), de.reshape(-1, 3))


def energy(op: SpectralElasticity, u: np.ndarray, v: np.ndarray) -> float:
    """``1/2 u . K u + 1/2 v . M v`` (``u``, ``v``: (n_nodes, 3)).

    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
    >>> sm = spectral_mesh(HEX_CORNERS, np.arange(8)[None], [True], 2)
    >>> op = spectral_elasticity(2, sm.points, sm.elements, 1.0, 1.0, 3.0)
    >>> energy(op, np.zeros((27, 3)), np.ones((27, 3)))              # 1/2 (3 * 8) * 3
    36.0
    """
    return float(0.5 * np.vdot(u, op.forces(u)) + 0.5 * np.vdot(v, op.mass[:, None] * v))


def max_frequency_squared(op: SpectralElasticity, inv_mass: np.ndarray | None = None,
                          iterations: int = POWER_ITERATIONS, seed: int = 0,
                          constrain=None) -> float:
    """The largest ``omega^2`` of ``M^-1 K`` by power iteration (the stable central
    difference step is ``dt < 2 / omega_max``).

    The Rayleigh quotient ``x.Kx / x.Mx`` approaches ``omega_max^2`` from below; it stops
    when it changes by less than :data:`POWER_TOLERANCE` (relative) or after
    ``iterations``: take a safety factor on the step (the explicit engines take 0.9).

    Parameters
    ----------
    inv_mass
        ``1 / m`` per component (n_nodes, 3), 0 at held components (default: all free).
    constrain
        Optional ``callable(x)`` applied in place to every iterate (e.g. the
        :func:`~.spectral_mesh.prolongate` of constrained nodes).

    Examples
    --------
    One free element of order 2 against the dense generalised eigenproblem
    ``K x = omega^2 M x``:

    >>> import numpy as np
    >>> from railvib_hpc.fem.reference import HEX_CORNERS
    >>> from railvib_hpc.fem.spectral_mesh import spectral_mesh
    >>> sm = spectral_mesh(HEX_CORNERS, np.arange(8)[None], [True], 2)
    >>> op = spectral_elasticity(2, sm.points, sm.elements, 2.0, 1.0, 1.0)
    >>> m = np.repeat(op.mass[sm.elements[0]], 3)                  # local order
    >>> exact = np.linalg.eigvalsh(element_matrices(op)[0] / np.sqrt(np.outer(m, m))).max()
    >>> bool(abs(max_frequency_squared(op) / exact - 1) < 1e-4)
    True
    """
    if inv_mass is None:
        inv_mass = np.repeat(1.0 / op.mass[:, None], 3, axis=1)
    x = np.random.default_rng(seed).standard_normal((op.n_nodes, 3)) * (inv_mass > 0)
    previous = 0.0
    for _ in range(iterations):
        if constrain is not None:
            constrain(x)
        kx = op.forces(x)
        mx = np.where(inv_mass > 0, 1.0 / np.where(inv_mass > 0, inv_mass, 1.0), 0.0) * x
        quotient = float(np.vdot(x, kx) / np.vdot(x, mx))
        y = inv_mass * kx
        x = y / np.abs(y).max()
        if abs(quotient - previous) <= POWER_TOLERANCE * quotient:
            break
        previous = quotient
    return quotient
