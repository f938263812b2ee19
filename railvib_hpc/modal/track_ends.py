"""The supported track ends (``track.ends = 'supported'``): the rail beyond the soil box on
an equivalent elastic foundation (pure numpy).

Beyond the soil box (``x < geometry.x1``, ``x > geometry.x4``) the flexible rail continues
for ``track.rigid_length`` (part ``rail``, :mod:`railvib_hpc.mesh.gmsh_model`) and rests,
at every sleeper position, on three springs and dashpots to fixed ground (3 x 3 node
blocks added to K and C like the absorbing faces' ones, :func:`~.boundary.boundary_node_blocks`):

* the vertical spring ``k_s`` per rail and support is ``track.end_stiffness``, or fitted
  (:func:`winkler_modulus`) so that a beam of the rail's ``EI`` on the Winkler
  foundation ``k = k_s / s`` (``s`` the sleeper spacing) has the modelled track's static
  point receptance at its middle: the wheel meets the same stiffness on both sides of the
  box's end, so no impulse enters the box. The longitudinal and lateral springs follow
  the pads' proportions (``pads.kx / pads.kz``, ``pads.ky / pads.kz``);
* the dashpots grow with the square of the distance ``d`` from the box, from zero at the
  box to ``track.end_damping`` times the critical damping ``2 sqrt(k_i m)`` of a bay's
  rail mass ``m = rho A s`` at the far end: a graded absorber, so a bending wave along
  the rail is damped out instead of reflected from the end (and the rigid-to-flexible
  jump of a wheel entering at the far end is damped before it reaches the box);
* the support at the far end carries half a bay (its tributary length).

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
    tributary = np.where(np.abs(d - ends.length) < POSITION_TOL, 0.5, 1.0)
    if kind == "spring":
        values = tributary[:, None] * k[None, :]
    else:
        rail = problem.material("rail").rho * problem.sections["rail"].area
        critical = 2.0 * np.sqrt(k * rail * ends.spacing)
        grade = ends.damping * (d / ends.length) ** 2
        values = (tributary * grade)[:, None] * critical[None, :]
    return nodes, np.einsum("ki,ij->kij", values, np.eye(3))


__all__ = ["POSITION_TOL", "point_deflection", "support_blocks", "support_nodes",
           "winkler_modulus"]
