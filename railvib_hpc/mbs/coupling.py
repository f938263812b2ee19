"""Wheel-rail coupling in modal coordinates: interpolation and force distribution.

A rail is described by its sorted node coordinates ``x_nodes`` (k,) and the
modal rows of those nodes: vertical displacement ``phi_w`` (m, k) of
mass-normalised modes and, optionally, the rotation about the lateral axis
``phi_r`` (m, k).

Sign convention for rotations: ``dw/dx = -phi_r``. This is the FE rotation
``ry`` of a rail running along +x with z up (right-hand rule: a positive
rotation about +y moves +x points downwards), i.e. what ANSYS or our own
beam elements store. Pass ``-phi_r`` if your data use ``dw/dx = +phi_r``.

With rotations the rail displacement under a wheel at ``x`` is the Hermite
cubic of the element containing ``x``; without rotations it is the linear
interpolation of the two node displacements. Linear interpolation has a
kink at every node: a rolling wheel then sees a slope discontinuity at each
node passage, which excites spurious impacts at high speed and converges
only with O(h^2) instead of O(h^4). Prefer rotations whenever the FE model
has them.

A point force ``F`` at ``x`` is distributed to the nodes with the *same* shape
functions, so the modal force is ``Q = Psi^T f = F * psi(x)`` where
``psi(x)`` (m,) is the interpolated modal row: by construction ``Q . q ==
F * w(x)`` (virtual work). Positions outside ``[x_nodes[0], x_nodes[-1]]``
are on the rigid rail: ``psi = 0``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def _as_positions(x: float | np.ndarray) -> np.ndarray:
    return np.atleast_1d(np.asarray(x, dtype=float))


def shape_functions(
    x_nodes: np.ndarray, x: float | np.ndarray, hermite: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Element index and shape-function values at positions ``x``.

    Parameters
    ----------
    x_nodes
        (k,) sorted node coordinates of the rail.
    x
        Scalar or (n,) positions.
    hermite
        True for cubic Hermite functions (displacement and rotation DOFs),
        False for linear functions (displacement DOFs only).

    Returns
    -------
    elem
        (n,) index ``i`` of the element ``[x_nodes[i], x_nodes[i+1]]`` containing
        each position (clipped to a valid element when outside).
    weights
        (n, 4) Hermite weights for ``(w_i, w'_i, w_{i+1}, w'_{i+1})`` where
        ``w'`` is ``dw/dx``; or (n, 2) linear weights for ``(w_i, w_{i+1})``.
        Zero rows for positions outside the flexible rail.
    inside
        (n,) True where the position lies on the flexible rail.
    """
    xn = np.asarray(x_nodes, dtype=float)
    xs = _as_positions(x)
    inside = (xs >= xn[0]) & (xs <= xn[-1])
    elem = np.clip(np.searchsorted(xn, xs, side="right") - 1, 0, xn.size - 2)
    h = xn[elem + 1] - xn[elem]
    xi = (xs - xn[elem]) / h
    if hermite:
        xi2 = xi * xi
        xi3 = xi2 * xi
        weights = np.stack(
            [1.0 - 3.0 * xi2 + 2.0 * xi3, h * (xi - 2.0 * xi2 + xi3), 3.0 * xi2 - 2.0 * xi3,
             h * (xi3 - xi2)],
            axis=1,
        )
    else:
        weights = np.stack([1.0 - xi, xi], axis=1)
    weights[~inside] = 0.0
    return elem, weights, inside


@dataclass(frozen=True)
class RailCoupling:
    """Modal description of one rail, for interpolation and force distribution.

    Parameters
    ----------
    x_nodes
        (k,) strictly increasing node coordinates [m].
    phi_w
        (m, k) vertical displacement of the (mass-normalised) modes at the nodes.
    phi_r
        (m, k) rotation about the lateral axis with ``dw/dx = -phi_r``, or None
        for linear interpolation (see the module notes: less accurate).
    """

    x_nodes: np.ndarray
    phi_w: np.ndarray
    phi_r: np.ndarray | None = None

    def __post_init__(self) -> None:
        xn = np.ascontiguousarray(self.x_nodes, dtype=float)
        pw = np.ascontiguousarray(self.phi_w, dtype=float)
        if xn.ndim != 1 or xn.size < 2 or np.any(np.diff(xn) <= 0.0):
            raise ValueError("x_nodes must be a strictly increasing 1-D array with >= 2 entries")
        if pw.ndim != 2 or pw.shape[1] != xn.size:
            raise ValueError(f"phi_w must have shape (m, {xn.size}), got {pw.shape}")
        object.__setattr__(self, "x_nodes", xn)
        object.__setattr__(self, "phi_w", pw)
        if self.phi_r is not None:
            pr = np.ascontiguousarray(self.phi_r, dtype=float)
            if pr.shape != pw.shape:
                raise ValueError(f"phi_r must have shape {pw.shape}, got {pr.shape}")
            object.__setattr__(self, "phi_r", pr)

    @property
    def n_modes(self) -> int:
        """Number of modes m."""
        return self.phi_w.shape[0]

    @property
    def hermite(self) -> bool:
        """True when rotations are available (cubic Hermite interpolation)."""
        return self.phi_r is not None

    def modal_rows(self, x: float | np.ndarray) -> np.ndarray:
        """Interpolated modal rows ``psi(x)``.

        Parameters
        ----------
        x
            Scalar or (n,) positions along the rail [m].

        Returns
        -------
        numpy.ndarray
            (m, n) array; column j is ``psi(x_j)`` so that ``w(x_j) = psi(x_j) . q``
            and a force ``F`` at ``x_j`` has modal force ``F * psi(x_j)``.
            Zero columns for positions on the rigid rail.
        """
        elem, wts, _ = shape_functions(self.x_nodes, x, self.hermite)
        pw = self.phi_w
        if self.hermite:
            pr = self.phi_r
            return (pw[:, elem] * wts[:, 0] - pr[:, elem] * wts[:, 1]
                    + pw[:, elem + 1] * wts[:, 2] - pr[:, elem + 1] * wts[:, 3])
        return pw[:, elem] * wts[:, 0] + pw[:, elem + 1] * wts[:, 1]

    def displacement(self, x: float | np.ndarray, q: np.ndarray) -> np.ndarray:
        """Rail vertical displacement ``w(x) = psi(x) . q``.

        Parameters
        ----------
        x
            Scalar or (n,) positions [m].
        q
            (m,) modal coordinates, or (nt, m) for a history.

        Returns
        -------
        numpy.ndarray
            (n,) or (nt, n) displacements (0 on the rigid rail).
        """
        return np.asarray(q, dtype=float) @ self.modal_rows(x)

    def modal_force(self, x: float | np.ndarray, forces: float | np.ndarray) -> np.ndarray:
        """Modal force ``Q = Psi^T f`` of point forces distributed with the same shape functions.

        Parameters
        ----------
        x
            Scalar or (n,) force positions [m].
        forces
            Scalar or (n,) forces in the direction of positive ``w`` [N].

        Returns
        -------
        numpy.ndarray
            (m,) modal force; forces on the rigid rail contribute nothing.
        """
        f = np.broadcast_to(np.asarray(forces, dtype=float), _as_positions(x).shape)
        return self.modal_rows(x) @ f


def contact_normal_rail(rail: RailCoupling, phi_v: np.ndarray, phi_rz: np.ndarray | None,
                        lateral_factor: float) -> RailCoupling:
    """Rail coupling along an inclined contact normal ``(0, lateral_factor, 1)``.

    The displacement of the rail along the normal is ``w + a v`` (``a =
    lateral_factor``, ``v`` the lateral displacement), and a normal force pushes
    the rail down and sideways by ``a`` times the force: both are the vertical
    coupling with the modal rows ``phi_w + a phi_v``. Rotations mix the same
    way: ``dv/dx = rz`` (rotation about z), so the effective ``phi_r`` (with
    ``d(w + a v)/dx = -phi_r``) is ``phi_ry - a phi_rz``.

    Parameters
    ----------
    rail
        Vertical coupling (``phi_w``, ``phi_r`` = ``ry``).
    phi_v
        (m, k) lateral displacement rows at the same nodes.
    phi_rz
        (m, k) rotation about the vertical axis, or None (linear interpolation).
    lateral_factor
        ``a``: ``+lambda`` for the rail at negative y, ``-lambda`` at positive y
        (the wheel pushes its rail outwards).

    Returns
    -------
    RailCoupling
        Coupling of the normal direction.
    """
    a = float(lateral_factor)
    pw = rail.phi_w + a * np.asarray(phi_v, dtype=float)
    pr = None
    if rail.phi_r is not None and phi_rz is not None:
        pr = rail.phi_r - a * np.asarray(phi_rz, dtype=float)
    return RailCoupling(rail.x_nodes, pw, pr)
