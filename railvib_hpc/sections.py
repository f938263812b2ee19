"""Beam cross-sections of the thesis's APDL script, computed from its ``SECDATA``.

The thesis's ANSYS BEAM188 elements take their section properties from the section
commands of Appendix A, not from Table I:

* rail: ``SECTYPE,1,BEAM,I`` with ``SECDATA,0.1524,0.07,0.19,0.0165,0.045,0.0175``. ANSYS
  reads the subtype ``I`` as ``W1, W2, W3, t1, t2, t3``: width of flange 1 (bottom) and of
  flange 2 (top), overall depth, the two flange thicknesses and the web thickness (ANSYS
  Command Reference, SECDATA, "Type: BEAM, Subtype: I"). Here: a 152.4 mm foot 16.5 mm
  thick, a 70 mm head 45 mm thick, a 17.5 mm web, 190 mm high;
* sleeper: ``SECTYPE,2,BEAM,QUAD`` with ``SECDATA,-0.135,-0.11,.135,-.11,.090,.11,-.090,.11``,
  the corners ``(y, z)`` of a quadrilateral: a symmetric trapezoid 0.27 m wide at the bottom,
  0.18 m at the top, 0.22 m high.

Formulas (each has a test against hand-computed or analytic values):

* area, centroid and second moments: exact, by rectangles (I) and by Green's theorem over
  the polygon (quadrilateral);
* torsion constant ``J``: computed the way ANSYS computes it for every BEAM188 section
  (ANSYS Theory Reference, "Beam section analysis"), by a finite-element solution of
  Saint-Venant torsion on a mesh of the section: the Prandtl stress function,
  ``laplace(phi) = -2``, ``phi = 0`` on the boundary, ``J = 2 int phi dA``, bilinear
  quadrilaterals on three meshes, extrapolated to zero element size with the observed
  order (Richardson). The closed forms of :func:`i_section_torsion_estimates` are the
  cross-checks: the thin-walled ``sum b t^3 / 3`` and the thick-walled formula of
  El Darwish & Johnston (1965, "Torsion of structural shapes", J. Struct. Div. ASCE
  91(ST1)) as given in AISC Design Guide 9 (Seaburg & Carter 1997, with zero fillet
  radius). For the rail's squat 70 x 45 mm head they are 40 % and 9 % above the
  Saint-Venant value (the formulas are fitted to rolled shapes with thin flanges);
* shear coefficients ``k`` (shear area ``k A``) of both bending planes: the energy method
  with the Jourawski shear-stress distribution, ``1/k = (A / I^2) int Q(s)^2 / b(s) ds``
  (the shear form factor, e.g. Pilkey, *Analysis and Design of Elastic Beams*, Wiley 2002;
  Gere & Timoshenko, *Mechanics of Materials*), exactly ``k = 5/6`` for a rectangle.
  ANSYS derives its factors from the numerical shear-stress field of the section; for
  compact sections the two differ by a few percent (Cowper 1966: rectangle
  ``10 (1 + nu) / (12 + 11 nu)`` = 0.85 at ``nu = 0.3``).

:data:`APDL_RAIL` and :data:`APDL_SLEEPER` hold the results (the schema's ``apdl``
defaults); ``tests/test_sections.py`` recomputes them.

Example
-------
>>> rail = i_section(*RAIL_SECDATA, cells=2)
>>> round(rail.area * 1e4, 2), round(rail.iyy * 1e8), round(rail.izz * 1e8)
(79.13, 3956, 621)
>>> sleeper = quad_section(SLEEPER_SECDATA, cells=8)
>>> round(sleeper.area * 1e4, 1), round(sleeper.iyy * 1e8), round(sleeper.izz * 1e8)
(495.0, 19699, 21718)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "APDL_RAIL",
    "APDL_SLEEPER",
    "RAIL_SECDATA",
    "SLEEPER_SECDATA",
    "SectionProperties",
    "apdl_rail_section",
    "apdl_sleeper_section",
    "i_section",
    "i_section_torsion_estimates",
    "plate_torsion_constant",
    "prandtl_torsion_constant",
    "quad_section",
    "strip_shear_coefficient",
]

#: Appendix A, ``SECTYPE,1,BEAM,I``: ``SECDATA,W1,W2,W3,t1,t2,t3`` of the rail [m].
RAIL_SECDATA = (0.1524, 0.07, 0.19, 0.0165, 0.045, 0.0175)
#: Appendix A, ``SECTYPE,2,BEAM,QUAD``: corners ``(yI, zI), (yJ, zJ), (yK, zK), (yL, zL)`` [m].
SLEEPER_SECDATA = ((-0.135, -0.11), (0.135, -0.11), (0.090, 0.11), (-0.090, 0.11))

#: El Darwish & Johnston junction coefficient ``alpha = 0.15 t/t1`` at zero fillet radius.
_JUNCTION_ALPHA = 0.15
#: Gauss points per linear-width segment for the shear-factor integrals (exact to ~1e-14).
_GAUSS_POINTS = 24


@dataclass(frozen=True)
class SectionProperties:
    """Properties of a beam cross-section (SI units).

    Attributes
    ----------
    area
        Area [m^2].
    iyy
        Second moment of area for bending in the vertical plane (about the horizontal
        centroidal axis) [m^4] — the schema's ``iyy``.
    izz
        Second moment for bending in the horizontal plane (about the vertical axis) [m^4].
    j
        Saint-Venant torsion constant [m^4].
    shear_coefficient_y, shear_coefficient_z
        Timoshenko shear coefficients of vertical and lateral bending (shear area ``k A``).
    centroid_height
        Height of the centroid above the section's lowest point [m].
    """

    area: float
    iyy: float
    izz: float
    j: float
    shear_coefficient_y: float
    shear_coefficient_z: float
    centroid_height: float

    def mass_per_length(self, density: float) -> float:
        """Mass per unit length [kg/m] at ``density`` [kg/m^3]."""
        return self.area * density


def plate_torsion_constant(b: float, t: float) -> float:
    """Roark's torsion constant of a solid rectangle ``b x t`` (any order of the sides).

    ``J = b t^3 [1/3 - 0.21 (t/b)(1 - t^4 / (12 b^4))]`` with ``b >= t`` (Young & Budynas,
    Roark's Formulas for Stress and Strain, 7th ed., Table 10.7 case 4; within 0.5 % of
    the exact series for all aspect ratios).
    """
    b, t = max(b, t), min(b, t)
    r = t / b
    return b * t**3 * (1.0 / 3.0 - 0.21 * r * (1.0 - r**4 / 12.0))


def strip_shear_coefficient(segments: Sequence[tuple[float, float, float, float]]) -> float:
    """Shear coefficient ``k`` of a section described by strips of linear width.

    The section is cut normal to the shear force into strips: ``segments`` lists
    ``(s0, s1, b0, b1)``, the width ``b`` varying linearly from ``b0`` at ``s0`` to ``b1``
    at ``s1``, contiguous and ascending in ``s``. With the Jourawski shear stress
    ``tau = V Q(s) / (I b(s))`` the shear strain energy equals that of a uniform stress
    on ``k A`` with ``1/k = (A / I^2) int Q^2 / b ds``.

    Returns
    -------
    float
        ``k`` (5/6 for a rectangle).
    """
    xg, wg = np.polynomial.legendre.leggauss(_GAUSS_POINTS)
    segs = [tuple(map(float, s)) for s in segments if s[1] > s[0]]
    # area and centroid
    area = sum(0.5 * (b0 + b1) * (s1 - s0) for s0, s1, b0, b1 in segs)
    first = 0.0
    for s0, s1, b0, b1 in segs:
        h = s1 - s0
        first += h * (b0 * (s0 + h / 3.0) + b1 * (s0 + 2.0 * h / 3.0)) / 2.0
    c = first / area

    def width(s, s0, s1, b0, b1):
        return b0 + (b1 - b0) * (s - s0) / (s1 - s0)

    def q_partial(s, s0, s1, b0, b1):
        """int_{s0}^{s} b(t) (t - c) dt (exact polynomial)."""
        # b(t) = b0 + g (t - s0);  integrate (b0 + g u)(u + s0 - c) du from 0 to s - s0
        g = (b1 - b0) / (s1 - s0)
        u = s - s0
        d = s0 - c
        return b0 * (u**2 / 2 + d * u) + g * (u**3 / 3 + d * u**2 / 2)

    inertia = 0.0
    for s0, s1, b0, b1 in segs:
        s = 0.5 * (s1 + s0) + 0.5 * (s1 - s0) * xg
        inertia += 0.5 * (s1 - s0) * np.sum(wg * width(s, s0, s1, b0, b1) * (s - c) ** 2)
    integral, q0 = 0.0, 0.0
    for s0, s1, b0, b1 in segs:
        s = 0.5 * (s1 + s0) + 0.5 * (s1 - s0) * xg
        b = width(s, s0, s1, b0, b1)
        q = q0 + q_partial(s, s0, s1, b0, b1)
        ok = b > 0.0
        integral += 0.5 * (s1 - s0) * np.sum(wg[ok] * q[ok] ** 2 / b[ok])
        q0 += q_partial(s1, s0, s1, b0, b1)
    return inertia**2 / (area * integral)


def i_section(w1: float, w2: float, w3: float, t1: float, t2: float, t3: float,
              cells: int = 8) -> SectionProperties:
    """ANSYS ``SECTYPE,,BEAM,I`` section from ``SECDATA,W1,W2,W3,t1,t2,t3``.

    Parameters
    ----------
    w1, w2
        Widths of flange 1 (bottom) and flange 2 (top) [m].
    w3
        Overall depth [m].
    t1, t2
        Thicknesses of flange 1 and flange 2 [m].
    t3
        Web thickness [m].
    cells
        Elements across the thinnest plate on the coarsest of the three torsion meshes
        (the others have 2x and 4x as many).

    Returns
    -------
    SectionProperties
        See the module notes for the formulas.

    Examples
    --------
    >>> s = i_section(0.1, 0.1, 0.2, 0.01, 0.01, 0.01, cells=2)   # a symmetric I
    >>> round(s.area * 1e4, 1)
    38.0
    """
    if min(w1, w2, w3, t1, t2, t3) <= 0 or t1 + t2 >= w3 or t3 > min(w1, w2):
        raise ValueError(f"not an I-section: SECDATA {w1, w2, w3, t1, t2, t3}")
    hw = w3 - t1 - t2
    rects = [(w1, t1, 0.5 * t1), (t3, hw, t1 + 0.5 * hw), (w2, t2, w3 - 0.5 * t2)]
    area = sum(b * h for b, h, _ in rects)
    zc = sum(b * h * z for b, h, z in rects) / area
    iyy = sum(b * h**3 / 12.0 + b * h * (z - zc) ** 2 for b, h, z in rects)
    izz = sum(h * b**3 / 12.0 for b, h, _ in rects)
    boxes = [(-w1 / 2, w1 / 2, 0.0, t1), (-t3 / 2, t3 / 2, t1, t1 + hw),
             (-w2 / 2, w2 / 2, t1 + hw, w3)]
    h0 = min(t1, t2, t3) / cells
    j = _extrapolated([prandtl_torsion_constant(*_rectangles_mesh(boxes, h0 / 2**k))
                       for k in range(3)])
    # shear: vertical force -> horizontal strips; lateral force -> vertical strips
    ky = strip_shear_coefficient([(0.0, t1, w1, w1), (t1, t1 + hw, t3, t3),
                                  (t1 + hw, w3, w2, w2)])
    edges = sorted({-w1 / 2, w1 / 2, -w2 / 2, w2 / 2, -t3 / 2, t3 / 2})

    def height(y: float) -> float:
        return t1 * (abs(y) < w1 / 2) + t2 * (abs(y) < w2 / 2) + hw * (abs(y) < t3 / 2)

    lateral = [(a, b, height(0.5 * (a + b)), height(0.5 * (a + b)))
               for a, b in zip(edges[:-1], edges[1:])]
    kz = strip_shear_coefficient(lateral)
    return SectionProperties(area, iyy, izz, j, ky, kz, zc)


def i_section_torsion_estimates(w1: float, w2: float, w3: float, t1: float, t2: float,
                                t3: float) -> dict[str, float]:
    """Closed-form torsion constants of an I-section (cross-checks of :func:`i_section`).

    Returns
    -------
    dict
        ``thin_walled``: ``sum b t^3 / 3`` over the two flanges and the web between them;
        ``el_darwish_johnston``: each flange by :func:`plate_torsion_constant`, the web
        ``d_w t_w^3 / 3``, plus ``alpha D^4`` at each web-flange junction with
        ``alpha = 0.15 t_min / t_max`` and ``D = (t_f^2 + t_w^2 / 4) / t_f`` (AISC Design
        Guide 9 with zero fillet radius).
    """
    hw = w3 - t1 - t2
    thin = (w1 * t1**3 + w2 * t2**3 + hw * t3**3) / 3.0
    j = plate_torsion_constant(w1, t1) + plate_torsion_constant(w2, t2) + hw * t3**3 / 3.0
    for tf in (t1, t2):
        alpha = _JUNCTION_ALPHA * min(tf, t3) / max(tf, t3)
        j += alpha * ((tf**2 + t3**2 / 4.0) / tf) ** 4
    return {"thin_walled": thin, "el_darwish_johnston": j}


def _extrapolated(values: Sequence[float]) -> float:
    """Richardson extrapolation of three results on meshes halved twice (observed order)."""
    a, b, c = values
    d1, d2 = b - a, c - b
    if d1 == 0.0 or d2 == 0.0 or d2 / d1 <= 0.0 or d2 / d1 >= 1.0:
        return c
    ratio = d1 / d2                       # 2^p
    return c + d2 / (ratio - 1.0)


def _rectangles_mesh(boxes: Sequence[tuple[float, float, float, float]], h: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear mesh of a union of axis-parallel rectangles ``(y0, y1, z0, z1)``.

    A tensor grid through every rectangle edge, each interval cut into pieces no longer
    than ``h``; the cells whose centre lies in a rectangle are kept.
    """
    def grid(values: list[float]) -> np.ndarray:
        v = sorted(set(values))
        pieces = [np.linspace(a, b, max(1, math.ceil((b - a) / h - 1e-9)) + 1)[:-1]
                  for a, b in zip(v[:-1], v[1:])]
        return np.concatenate([*pieces, [v[-1]]])

    y = grid([v for r in boxes for v in r[:2]])
    z = grid([v for r in boxes for v in r[2:]])
    yy, zz = np.meshgrid(y, z, indexing="ij")
    pts = np.column_stack([yy.ravel(), zz.ravel()])
    idx = np.arange(y.size * z.size).reshape(y.size, z.size)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]],
                     axis=-1).reshape(-1, 4)
    centre = pts[quads].mean(axis=1)
    inside = np.zeros(len(quads), dtype=bool)
    for y0, y1, z0, z1 in boxes:
        inside |= ((centre[:, 0] > y0) & (centre[:, 0] < y1)
                   & (centre[:, 1] > z0) & (centre[:, 1] < z1))
    quads = quads[inside]
    used = np.unique(quads)
    renumber = np.full(len(pts), -1, dtype=np.int64)
    renumber[used] = np.arange(used.size)
    return pts[used], renumber[quads]


def _polygon_moments(pts: np.ndarray) -> tuple[float, float, float, float, float]:
    """Area, centroid (y, z) and centroidal second moments of a counter-clockwise polygon."""
    y, z = pts[:, 0], pts[:, 1]
    y1, z1 = np.roll(y, -1), np.roll(z, -1)
    cross = y * z1 - y1 * z
    area = 0.5 * cross.sum()
    cy = ((y + y1) * cross).sum() / (6.0 * area)
    cz = ((z + z1) * cross).sum() / (6.0 * area)
    i_yaxis = ((y**2 + y * y1 + y1**2) * cross).sum() / 12.0   # int y^2 dA
    i_zaxis = ((z**2 + z * z1 + z1**2) * cross).sum() / 12.0   # int z^2 dA
    return area, cy, cz, i_zaxis - area * cz**2, i_yaxis - area * cy**2


def _quad_mesh(corners: np.ndarray, ng: int, nh: int) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear-mapped structured mesh of a convex quadrilateral: points and quads."""
    u, v = np.meshgrid(np.linspace(0, 1, ng + 1), np.linspace(0, 1, nh + 1), indexing="ij")
    n = np.stack([(1 - u) * (1 - v), u * (1 - v), u * v, (1 - u) * v], axis=-1)
    pts = (n @ corners).reshape(-1, 2)
    idx = np.arange((ng + 1) * (nh + 1)).reshape(ng + 1, nh + 1)
    quads = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]],
                     axis=-1).reshape(-1, 4)
    return pts, quads


def prandtl_torsion_constant(points: np.ndarray, quads: np.ndarray) -> float:
    """Saint-Venant torsion constant of a section meshed with bilinear quadrilaterals.

    Solves ``laplace(phi) = -2`` with ``phi = 0`` on the boundary (edges used by one
    quadrilateral only: a simply connected section) and returns ``J = 2 int phi dA``.
    Second-order accurate in the element size for smooth solutions.

    Parameters
    ----------
    points
        (n, 2) node coordinates [m].
    quads
        (e, 4) counter-clockwise node indices.

    Returns
    -------
    float
        ``J`` [m^4].
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    points = np.asarray(points, dtype=float)
    quads = np.asarray(quads, dtype=np.int64)
    g = 1.0 / math.sqrt(3.0)
    gauss = [(-g, -g), (g, -g), (g, g), (-g, g)]
    xe = points[quads]                                    # (e, 4, 2)
    ke = np.zeros((len(quads), 4, 4))
    fe = np.zeros((len(quads), 4))
    sxi = np.array([-1.0, 1.0, 1.0, -1.0])
    seta = np.array([-1.0, -1.0, 1.0, 1.0])
    for xi, eta in gauss:
        shape = 0.25 * (1 + sxi * xi) * (1 + seta * eta)
        dn = 0.25 * np.stack([sxi * (1 + seta * eta), seta * (1 + sxi * xi)], axis=1)  # (4, 2)
        jac = np.einsum("eai,aj->eij", xe, dn)           # (e, 2, 2): d x_i / d xi_j
        det = np.linalg.det(jac)
        grad = np.einsum("aj,eji->eai", dn, np.linalg.inv(jac))  # (e, 4, 2)
        ke += np.einsum("eai,ebi->eab", grad, grad) * det[:, None, None]
        fe += 2.0 * shape[None, :] * det[:, None]
    n = len(points)
    rows = np.repeat(quads, 4, axis=1).ravel()
    cols = np.tile(quads, (1, 4)).ravel()
    k = sp.csr_matrix((ke.ravel(), (rows, cols)), shape=(n, n))
    f = np.bincount(quads.ravel(), weights=fe.ravel(), minlength=n)
    edges = np.sort(np.stack([quads, np.roll(quads, -1, axis=1)], axis=-1).reshape(-1, 2),
                    axis=1)
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    boundary = np.unique(uniq[count == 1])
    free = np.setdiff1d(np.arange(n), boundary)
    phi = np.zeros(n)
    phi[free] = spsolve(k[free][:, free].tocsc(), f[free])
    return float(f @ phi)


def quad_section(corners: Sequence[tuple[float, float]], cells: int = 32) -> SectionProperties:
    """ANSYS ``SECTYPE,,BEAM,QUAD`` section from its four corners ``(y, z)``.

    Area and second moments are exact; ``J`` is the Richardson extrapolation of three
    Prandtl solutions on ``cells``, ``2 cells`` and ``4 cells`` bilinear elements per
    side; the shear
    coefficients follow from the strip widths (the quadrilateral must be symmetric about
    the vertical axis with horizontal top and bottom edges, like the sleeper's trapezoid).

    Parameters
    ----------
    corners
        Four ``(y, z)`` points, counter-clockwise [m].
    cells
        Elements per side of the coarsest torsion mesh.

    Returns
    -------
    SectionProperties
    """
    pts = np.asarray(corners, dtype=float)
    if pts.shape != (4, 2):
        raise ValueError(f"a QUAD section has 4 corners (y, z), got {pts.shape}")
    area, cy, cz, iyy, izz = _polygon_moments(pts)
    if area <= 0:
        raise ValueError("QUAD corners must be counter-clockwise and enclose an area")
    zlo, zhi = pts[:, 1].min(), pts[:, 1].max()
    bottom = pts[np.isclose(pts[:, 1], zlo)]
    top = pts[np.isclose(pts[:, 1], zhi)]
    if len(bottom) != 2 or len(top) != 2 or not math.isclose(cy, 0.0, abs_tol=1e-12 * zhi):
        raise ValueError("shear coefficients need a trapezoid symmetric about y = 0 with "
                         "horizontal top and bottom edges")
    j = _extrapolated([prandtl_torsion_constant(*_quad_mesh(pts, cells * 2**k, cells * 2**k))
                       for k in range(3)])
    wb = float(np.ptp(bottom[:, 0]))
    wt = float(np.ptp(top[:, 0]))
    ky = strip_shear_coefficient([(zlo, zhi, wb, wt)])
    # lateral: vertical strips of height h(y); full height over the narrower edge
    h = zhi - zlo
    half_in, half_out = 0.5 * min(wb, wt), 0.5 * max(wb, wt)
    kz = strip_shear_coefficient([(-half_out, -half_in, 0.0, h), (-half_in, half_in, h, h),
                                  (half_in, half_out, h, 0.0)])
    return SectionProperties(area, iyy, izz, j, ky, kz, cz - zlo)


def apdl_rail_section() -> SectionProperties:
    """The rail of Appendix A computed from :data:`RAIL_SECDATA` (about 2 s)."""
    return i_section(*RAIL_SECDATA)


def apdl_sleeper_section() -> SectionProperties:
    """The sleeper of Appendix A computed from :data:`SLEEPER_SECDATA` (about 1 s)."""
    return quad_section(SLEEPER_SECDATA)


#: :func:`apdl_rail_section`, 4-5 significant digits (``tests/test_sections.py``
#: recomputes it): A 79.13 cm^2 (60.93 kg/m at 7700 kg/m^3), I 3956 / 621.1 cm^4,
#: J 1.851e-6 m^4, k 0.4214 / 0.7531, centroid 92.24 mm above the foot.
APDL_RAIL = SectionProperties(area=79.1335e-4, iyy=3956.04e-8, izz=621.060e-8,
                              j=1.8511e-6, shear_coefficient_y=0.42142,
                              shear_coefficient_z=0.75307, centroid_height=0.092244)
#: :func:`apdl_sleeper_section`: A 495 cm^2, I 19,699 / 21,718 cm^4, J 3.390e-4 m^4,
#: k 0.8328 / 0.8634.
APDL_SLEEPER = SectionProperties(area=495.0e-4, iyy=19698.8e-8, izz=21718.1e-8,
                                 j=3.3901e-4, shear_coefficient_y=0.83283,
                                 shear_coefficient_z=0.86345, centroid_height=0.10267)
