"""The supported track ends (``track.ends = 'supported'``): the rail beyond the soil box on
an equivalent elastic foundation (pure numpy).

Beyond the soil box (``x < geometry.x1``, ``x > geometry.x4``) the flexible rail continues
for ``track.rigid_length`` (part ``rail``, :mod:`railvib_hpc.mesh.gmsh_model`) and rests,
at every sleeper position, on three springs and dashpots to fixed ground (3 x 3 node
blocks added to K and C like the absorbing faces' ones, :func:`~.boundary.boundary_node_blocks`):

* the vertical spring ``k_s`` per rail and support is ``track.end_stiffness``, or fitted
  (:func:`fit_stiffness`) so that the supported rail as modelled (its Timoshenko
  elements on springs at every sleeper spacing ``s``) has the modelled track's static
  point receptance at the box's middle: the wheel meets the same stiffness on both
  sides of the box's end, so no impulse enters the box. The fit starts from the Winkler
  equivalent ``k = k_s / s`` of the beam-on-elastic-foundation formula
  (:func:`winkler_modulus`). The longitudinal and lateral springs follow
  the pads' proportions (``pads.kx / pads.kz``, ``pads.ky / pads.kz``);
* the dashpots grow with the square of the distance ``d`` from the box, from zero at the
  box to ``track.end_damping`` times the critical damping ``2 sqrt(k_i m)`` of a bay's
  rail mass ``m = rho A s`` at the far end: a graded absorber, so a bending wave along
  the rail is damped out instead of reflected from the end (and the rigid-to-flexible
  jump of a wheel entering at the far end is damped before it reaches the box);
* the rail's node at each far end is clamped (all six DOFs fixed, :data:`FAR_ENDS`):
  a wheel rolling on or off the modelled rail there meets a deflection that starts from
  zero continuously (the wheels beyond the modelled rail ride on rigid ground at the
  rail's height), as at today's rigid joints, but a section's length away from the box
  and where the dashpots are strongest. A free end would be 2-4 times softer than the
  track (a semi-infinite beam's end), and a wheel leaving it onto the rigid ground would
  climb the rail's whole deflection: measured, 10 times the static wheel load.

The beam-on-elastic-foundation reference (Hetenyi 1946): a point load ``F`` on an infinite
beam on a Winkler foundation ``k`` deflects it by ``w0 = F beta / (2 k)``, ``beta = (k /
(4 EI))^(1/4)`` (:func:`point_deflection`).
"""

from __future__ import annotations

import numpy as np

from ..mesh.model import Mesh
from ..problem import Problem, TrackEnds

#: Tolerance on positions along the track [m] (node coordinates come from gmsh in double
#: precision; the sleeper grid's positions are exact to far below this).
POSITION_TOL = 1e-6


def point_deflection(force: float, modulus: float, ei: float) -> float:
    """Static deflection under a point load on an infinite beam on a Winkler foundation.

    Parameters
    ----------
    force
        Point load [N].
    modulus
        Foundation modulus k [N/m^2] (stiffness per unit length of beam).
    ei
        Bending stiffness of the beam [N m^2].

    Returns
    -------
    float
        ``w0 = F beta / (2 k)``, ``beta = (k / (4 EI))^(1/4)`` [m] (Hetenyi 1946).
    """
    beta = (modulus / (4.0 * ei)) ** 0.25
    return force * beta / (2.0 * modulus)


def winkler_modulus(receptance: float, ei: float) -> float:
    """The Winkler modulus whose point receptance is ``receptance`` (inverse of
    :func:`point_deflection` with ``F = 1``): ``k = (2 w0 (4 EI)^(1/4))^(-4/3)`` [N/m^2].

    Parameters
    ----------
    receptance
        Static deflection under a unit load [m/N], > 0.
    ei
        Bending stiffness of the beam [N m^2].
    """
    if not receptance > 0:
        raise ValueError(f"the receptance must be > 0, got {receptance!r}")
    return (2.0 * receptance * (4.0 * ei) ** 0.25) ** (-4.0 / 3.0)


#: Sleeper bays on each side of the load in :func:`supported_rail_receptance`: the
#: deflection of a beam on an elastic foundation decays as ``exp(-beta x)``, and 40 bays
#: of 0.6 m are more than 20 / beta for any foundation stiffer than 2e5 N/m^2.
RECEPTANCE_BAYS = 40
#: Relative tolerance and most iterations of the stiffness fit (:func:`fit_stiffness`).
FIT_RTOL, FIT_MAX_ITER = 1e-10, 50


def supported_rail_receptance(problem: Problem, stiffness: float, spacing: float,
                              per_bay: int, bays: int = RECEPTANCE_BAYS) -> float:
    """Static vertical deflection under a unit load of the supported rail as modelled.

    The rail's Timoshenko beam elements (:func:`~railvib_hpc.fem.beam.beam_stiffness`,
    vertical plane), ``per_bay`` per sleeper bay, on vertical springs ``stiffness`` at
    every ``spacing``, ``bays`` bays on each side of the load, which sits on a support.

    Returns
    -------
    float
        The deflection at the load [m/N].
    """
    from ..fem.beam import beam_stiffness, shear_modulus

    n = 2 * bays * per_bay
    x = np.linspace(-bays * spacing, bays * spacing, n + 1)
    pts = np.stack([x, np.zeros_like(x), np.zeros_like(x)], axis=1)
    conn = np.stack([np.arange(n), np.arange(1, n + 1)], axis=1)
    sec, mat = problem.sections["rail"], problem.material("rail")
    ke = beam_stiffness(pts[conn], mat.E, shear_modulus(mat.E, mat.nu), sec.area, sec.iyy,
                        sec.izz, sec.j, sec.shear_coefficient_y, sec.shear_coefficient_z,
                        [0.0, 0.0, 1.0])
    plane = np.array([2, 4, 8, 10])                    # uz, ry of both nodes
    ke = ke[:, plane][:, :, plane]
    dofs = (2 * conn[:, :, None] + np.arange(2)).reshape(n, 4)
    K = np.zeros((2 * (n + 1), 2 * (n + 1)))
    np.add.at(K, (dofs[:, :, None], dofs[:, None, :]), ke)
    supports = 2 * np.arange(0, n + 1, per_bay)
    K[supports, supports] += stiffness
    f = np.zeros(2 * (n + 1))
    f[n] = 1.0                                         # uz of the middle node (n / 2)
    return float(np.linalg.solve(K, f)[n])


def fit_stiffness(receptance: float, problem: Problem, spacing: float, per_bay: int) -> float:
    """The support stiffness whose :func:`supported_rail_receptance` is ``receptance``.

    Starts from the Winkler equivalent (:func:`winkler_modulus` times ``spacing``) and
    iterates ``k <- k (w(k) / w)^(4/3)`` (the Winkler beam's ``w ~ k^(-3/4)``) to
    :data:`FIT_RTOL`: the fit holds for the rail's shear deformation and the discrete
    supports too.
    """
    ei = problem.material("rail").E * problem.sections["rail"].iyy
    k = winkler_modulus(receptance, ei) * spacing
    for _ in range(FIT_MAX_ITER):
        w = supported_rail_receptance(problem, k, spacing, per_bay)
        if abs(w / receptance - 1.0) < FIT_RTOL:
            return k
        k *= (w / receptance) ** (4.0 / 3.0)
    raise ValueError(f"the support stiffness fit to the receptance {receptance:.4g} m/N did "
                     f"not converge in {FIT_MAX_ITER} iterations (last k = {k:.4g} N/m)")


#: Name of the node set of the clamped far ends in the DOF map's rules
#: (:func:`~.boundary.problem_dofmap`).
FAR_ENDS = "track_far_ends"


def far_end_nodes(mesh: Mesh, ends: TrackEnds) -> np.ndarray:
    """The rail nodes at the far ends of the supported sections (none with rigid ends)."""
    if not ends.supported:
        return np.zeros(0, np.int64)
    nodes, d = support_nodes(mesh, ends)
    return nodes[np.abs(d - ends.length) < POSITION_TOL]


def support_nodes(mesh: Mesh, ends: TrackEnds) -> tuple[np.ndarray, np.ndarray]:
    """The rail nodes of the supported ends that rest on a support.

    Returns
    -------
    nodes : ndarray (k,)
        Rail nodes beyond the soil box at a whole number of sleeper spacings from it.
    distance : ndarray (k,)
        Their distance from the box [m].
    """
    if not ends.supported:
        return np.zeros(0, np.int64), np.zeros(0)
    rails = mesh.rail_nodes()
    nodes = rails[rails >= 0]
    x = mesh.points[nodes, 0]
    d = np.maximum(ends.box_start - x, x - ends.box_end)
    bays = d / ends.spacing
    on_grid = (d > POSITION_TOL) & (np.abs(bays - np.round(bays)) * ends.spacing
                                    < POSITION_TOL)
    order = np.argsort(nodes[on_grid])
    return nodes[on_grid][order], d[on_grid][order]


def support_blocks(mesh: Mesh, problem: Problem, kind: str
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The supports' 3 x 3 node blocks on ``(ux, uy, uz)``: springs or dashpots.

    Parameters
    ----------
    mesh, problem
        The model; ``problem.track_ends`` with its (given or fitted) stiffness; nothing
        while that is 0 (not fitted yet) or with rigid ends.
    kind
        ``"spring"`` (K) or ``"dashpot"`` (C).

    Returns
    -------
    nodes : ndarray (k,)
    blocks : ndarray (k, 3, 3)
        Diagonal blocks (see the module notes).
    """
    if kind not in ("dashpot", "spring"):
        raise ValueError(f"kind must be 'dashpot' or 'spring', got {kind!r}")
    ends, pads = problem.track_ends, problem.pads
    nodes, d = support_nodes(mesh, ends)
    if len(nodes) == 0 or ends.stiffness <= 0.0:
        return np.zeros(0, np.int64), np.zeros((0, 3, 3))
    k = ends.stiffness * np.array([pads.kx / pads.kz, pads.ky / pads.kz, 1.0])
    tributary = np.where(np.abs(d - ends.length) < POSITION_TOL, 0.5, 1.0)  # (clamped)
    if kind == "spring":
        values = tributary[:, None] * k[None, :]
    else:
        rail = problem.material("rail").rho * problem.sections["rail"].area
        critical = 2.0 * np.sqrt(k * rail * ends.spacing)
        grade = ends.damping * (d / ends.length) ** 2
        values = (tributary * grade)[:, None] * critical[None, :]
    return nodes, np.einsum("ki,ij->kij", values, np.eye(3))


__all__ = ["FAR_ENDS", "POSITION_TOL", "far_end_nodes", "fit_stiffness", "point_deflection",
           "support_blocks", "support_nodes", "supported_rail_receptance", "winkler_modulus"]
