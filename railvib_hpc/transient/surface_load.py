"""Vertical point loads moving over the soil surface, without a track (docs/transient.md).

The load of the moving-load verification (:mod:`railvib_hpc.fem.halfspace`, STEM's
"moving load on soil"): ``n`` vertical forces ``P_j`` (downwards) at ``x_j(t) = x_start +
offset_j + c t`` on the line ``y = y_load`` of the ground surface, each switched on by a
smooth ramp ``s(t) = sin^2(pi t / (2 T_ramp))`` over ``T_ramp`` (then 1), so that the start
radiates little, optionally varying as ``cos(2 pi f_0 t)`` (the moving harmonic load of
:mod:`railvib_hpc.fem.halfspace_line`) and spread along x (:func:`spreading`). A point force is the
consistent nodal load of the element under it: the trilinear shape functions at its
reference coordinates in that hexahedron (the four nodes of the element face it stands
on), located once for every step of the run (:func:`railvib_hpc.mesh.search.locate`); a
spread load is a sum of such points. A load that has left the surface (past the end of the
soil) is off.

The loads are :data:`~railvib_hpc.transient.integrate.SparseLoad` pairs, the ``prescribed``
load of both engines (:class:`~.integrate.DirectSolver`, :class:`~.explicit.ExplicitSolver`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..fem.reference import hex_shape_values
from ..mesh.model import Mesh
from ..mesh.search import locate

__all__ = ["MovingSurfaceLoad", "SurfaceLoadPath", "ramp", "run_up_distance", "spreading"]

#: Largest distance between the points of a spread load, in units of the shortest element
#: edge along x: eight points per element, so the nodal shares vary smoothly.
SPREAD_SPACING = 0.125
#: Relative tolerance of "on the surface": a load point must lie within this fraction of
#: the soil's height of its top (the ground level).
SURFACE_TOLERANCE = 1e-9


def ramp(t: np.ndarray, duration: float) -> np.ndarray:
    """``sin^2(pi t / (2 T))`` for ``0 <= t < T``, 1 after (0 before): the load's smooth
    switch-on (continuous slope; ``duration = 0``: a step at ``t = 0``)."""
    t = np.asarray(t, dtype=float)
    if duration <= 0:
        return (t >= 0).astype(float)
    return np.where(t < 0, 0.0, np.where(t < duration,
                                         np.sin(0.5 * math.pi * t / duration) ** 2, 1.0))


def run_up_distance(t: np.ndarray, duration: float) -> np.ndarray:
    """``int_0^t ramp(tau, T) dtau`` [s]: the distance, over the final speed, a load covers
    by ``t`` when its speed grows as :func:`ramp` over ``T = duration`` (``t / 2 - T / (2 pi)
    sin(pi t / T)`` during it, ``t - T / 2`` after: the run-up costs ``T / 2``).

    >>> run_up_distance(np.array([0.5, 2.0]), 1.0).round(4).tolist()
    [0.0908, 1.5]
    """
    t = np.maximum(np.asarray(t, dtype=float), 0.0)
    if duration <= 0:
        return t
    during = 0.5 * t - duration / (2.0 * math.pi) * np.sin(math.pi * t / duration)
    return np.where(t < duration, during, t - 0.5 * duration)


def spreading(half_width: float, spacing: float) -> tuple[np.ndarray, np.ndarray]:
    """Offsets ``s`` and weights (summing to 1) of a load spread as ``(1 + cos(pi s / a))
    / (2 a)`` over ``|s| <= a``: the midpoint rule with at most ``spacing`` between points
    (one point at 0 for ``a = 0``).

    A point load moving over the nodes of a grid of size ``h`` pulses at ``c / h`` (its
    nodal shares change slope at every node) and radiates grid waves; the spreading's
    spectrum at the grid's wavenumbers is small for ``a >= 2 h`` (``cos^2``: it falls as
    ``k^-3``), and the field of the spread load is the point load's convolved with it
    (:mod:`railvib_hpc.fem.halfspace`; at distances ``>> a`` differs by ``O((a / d)^2)``).
    """
    if half_width <= 0:
        return np.zeros(1), np.ones(1)
    m = max(2, int(math.ceil(2.0 * half_width / spacing)))
    s = -half_width + (np.arange(m) + 0.5) * (2.0 * half_width / m)
    w = 1.0 + np.cos(math.pi * s / half_width)
    return s, w / w.sum()


@dataclass(frozen=True)
class SurfaceLoadPath:
    """Where and how the surface loads move.

    Attributes
    ----------
    forces
        (n,) downward force of each load [N].
    offsets
        (n,) position of each load along x relative to the leading one (<= 0) [m].
    x_start
        Position of the leading load at ``t = 0`` [m].
    y
        The line the loads run on [m].
    speed
        Speed along +x [m/s].
    ramp_time
        Duration of the switch-on :func:`ramp` of the forces [s].
    run_up
        Duration of the loads' run-up [s]: their speed grows as :func:`ramp` from 0 to
        ``speed`` over this time (0: at ``speed`` from t = 0), the start of loads standing
        in static equilibrium at t = 0 (``load.start = 'static'``), which then accelerate
        smoothly instead of jumping to their speed (:func:`run_up_distance`).
    half_width
        Half-width ``a`` of each load's spreading along x [m] (0: a point load): the force
        is spread as ``(1 + cos(pi s / a)) / (2 a)`` over ``|s| <= a`` (:func:`spreading`).
    frequency
        Each force varies as ``cos(2 pi f t)`` [Hz] (0: constant): the moving harmonic
        load (the reference :mod:`railvib_hpc.fem.halfspace_line`).
    """

    forces: np.ndarray
    offsets: np.ndarray
    x_start: float
    y: float
    speed: float
    ramp_time: float
    half_width: float = 0.0
    frequency: float = 0.0
    run_up: float = 0.0

    def positions(self, t: np.ndarray) -> np.ndarray:
        """(nt, n) x of every load at the times ``t``."""
        t = np.asarray(t, dtype=float)
        travelled = self.speed * run_up_distance(t, self.run_up)
        return self.x_start + np.asarray(self.offsets)[None, :] + travelled[:, None]

    def amplitudes(self, t: np.ndarray) -> np.ndarray:
        """(nt, n) downward force of every load at the times ``t`` [N]."""
        t = np.asarray(t, dtype=float)
        shape = ramp(t, self.ramp_time)
        if self.frequency:
            shape = shape * np.cos(2.0 * math.pi * self.frequency * t)
        return shape[:, None] * np.asarray(self.forces, float)[None, :]


class MovingSurfaceLoad:
    """The nodal loads of a :class:`SurfaceLoadPath` at every step of a run.

    Parameters
    ----------
    mesh
        The model (its top, ``max z`` of the soil, is the ground surface).
    dof_index
        (n_nodes, k >= 3) global DOF of each node's ``ux, uy, uz`` (-1: constrained).
    path
        The loads.
    dt, nt
        Time step [s] and steps: loads at ``t = n dt``, ``n = 0 .. nt``.
    ground
        z of the ground surface [m] (default: the mesh's highest node).

    Raises
    ------
    ValueError
        No load stands on the soil surface at any step (the line outside the soil, or
        ``ground`` not its top).
    """

    def __init__(self, mesh: Mesh, dof_index: np.ndarray, path: SurfaceLoadPath, dt: float,
                 nt: int, ground: float | None = None):
        z_top = float(mesh.points[:, 2].max()) if ground is None else float(ground)
        height = float(np.ptp(mesh.points[:, 2])) or 1.0
        t = np.arange(nt + 1) * dt
        x = path.positions(t)                                      # (nt + 1, n)
        edges = np.diff(np.unique(np.round(mesh.points[:, 0], 9)))
        offsets, share = spreading(path.half_width,
                                   SPREAD_SPACING * float(edges.min()) if edges.size else 1.0)
        xs = x[:, :, None] + offsets[None, None, :]                # (nt + 1, n, m)
        pts = np.stack([xs.ravel(), np.full(xs.size, path.y),
                        np.full(xs.size, z_top - SURFACE_TOLERANCE * height)], axis=1)
        elem, xi = locate(pts, mesh)
        m = offsets.size
        n = x.shape[1]
        elem = elem.reshape(nt + 1, n * m)
        xi = xi.reshape(nt + 1, n * m, 3)
        on = elem >= 0
        if not on.any():
            lo, hi = mesh.points.min(axis=0), mesh.points.max(axis=0)
            raise ValueError(f"the loads on y = {path.y:g} m never stand on the soil surface "
                             f"z = {z_top:g} m (x from {x.min():g} to {x.max():g} m; the "
                             f"soil spans x {lo[0]:g} .. {hi[0]:g}, y {lo[1]:g} .. "
                             f"{hi[1]:g} m)")
        weights = np.zeros((nt + 1, n * m, 8))
        weights[on] = hex_shape_values(np.clip(xi[on], -1.0, 1.0))
        uz = np.asarray(dof_index)[:, 2]
        dofs = np.where(on[..., None], uz[mesh.hexes[np.maximum(elem, 0)]], -1)
        amp = np.repeat(path.amplitudes(t), m, axis=1) * np.tile(share, x.shape[1])
        values = -amp[..., None] * weights                         # downwards: -z
        dofs = np.where(values != 0.0, dofs, -1)
        self._dofs, self._values = dofs, values
        self.on_surface = on.reshape(nt + 1, x.shape[1], m).any(axis=2)
        self.x = x

    def __call__(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """``(dofs, values)`` of step ``n``: the nodal forces of every load."""
        return self._dofs[n], self._values[n]

    def total_force(self, n: int) -> float:
        """Sum of the vertical nodal forces of step ``n`` (-P for a load on free nodes)."""
        return float(self._values[n][self._dofs[n] >= 0].sum())
