"""Probe histories straight from the modal basis (exact and cheap; rank 0, serial).

Each probe point is located in the hexahedral mesh (:func:`railvib_hpc.mesh.search.locate`:
containing element and reference coordinates ``xi``), the mode shapes of the element's 8
nodes are interpolated with the trilinear shape functions to ``phi_probe`` (m, 3), and the
histories follow as ``u(t) = q(t) @ phi_probe`` (likewise velocity and acceleration). This
is exactly the interpolation of the reconstructed nodal field at that point (the
superposition and the interpolation are both linear), at a cost of O(m) per step instead
of O(m n).

Probes are the named points of ``/mesh/probes`` in ``modes.h5`` plus user coordinates.
Extra bases (static correction) are interpolated the same way and added like modes.

The probe histories are written to ``probes.h5`` and ``probes/<name>.csv`` by the
format's module, :mod:`railvib_hpc.io.formats.probes` (layout, writers, reader, check;
:func:`write_probes_h5`, :func:`write_probes_csv`, :func:`read_probes` and
:class:`ProbesFileError` are re-exported here).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..errors import UserError
from ..fem.reference import hex_shape_values
from ..io.formats.probes import (  # noqa: F401 (re-exported: the format's writers, reader)
    CSV_HEADER,
    ProbesFileError,
    read_probes,
    write_probes_csv,
    write_probes_h5,
)
from ..mesh.model import Mesh
from ..mesh.search import locate
from ..schema import DEFAULT_PROBE_ROLE, PROBE_ROLES
from .fields import ExtraBasis

#: Column names of the probe CSV files.

#: User probes: ``{name: (x, y, z)}`` or a sequence of ``(x, y, z)`` (named ``user_1``, ...).
UserProbes = Mapping[str, Sequence[float]] | Sequence[Sequence[float]]

class ProbeError(UserError):
    """A probe point that cannot be used (outside the meshed solids, bad coordinates)."""


def _search_mesh(f) -> Mesh:
    """The hexahedra of an open ``modes.h5`` as a :class:`Mesh` for point location."""
    return Mesh(points=f["mesh/points"][()], hexes=f["mesh/hexes"][()],
                hex_part=f["mesh/hex_part"][()], lines=np.zeros((0, 2), np.int64),
                line_part=np.zeros(0, np.int32))


def mesh_probes(modes_path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The named probe points stored in ``/mesh/probes`` of ``modes.h5`` (name -> (3,))."""
    import h5py

    with h5py.File(modes_path, "r") as f:
        if "mesh/probes/names" not in f:
            return {}
        names = [n.decode() if isinstance(n, bytes) else str(n)
                 for n in f["mesh/probes/names"][()]]
        coords = f["mesh/probes/coords"][()].reshape(-1, 3)
    return dict(zip(names, coords))


def mesh_probe_roles(modes_path: str | os.PathLike) -> dict[str, str] | None:
    """Roles of the named probes in ``/mesh/probes/roles`` of ``modes.h5`` (name -> role;
    a probe stored without one gets ``"ground"``); None when the file has no roles (written
    by a version before probes had roles)."""
    import h5py

    with h5py.File(modes_path, "r") as f:
        if "mesh/probes/names" not in f:
            return {}
        if "mesh/probes/roles" not in f:
            return None
        names = [n.decode() if isinstance(n, bytes) else str(n)
                 for n in f["mesh/probes/names"][()]]
        roles = [r.decode() if isinstance(r, bytes) else str(r)
                 for r in f["mesh/probes/roles"][()]]
    return {n: r or DEFAULT_PROBE_ROLE for n, r in zip(names, roles)}


def user_probe_dict(user_probes: UserProbes) -> dict[str, np.ndarray]:
    """Normalise user probes to ``{name: (3,)}`` (unnamed ones become ``user_1``, ...)."""
    if isinstance(user_probes, Mapping):
        items = list(user_probes.items())
    else:
        items = [(f"user_{i + 1}", c) for i, c in enumerate(user_probes)]
    out = {}
    for name, c in items:
        xyz = np.asarray(c, dtype=float).reshape(-1)
        if xyz.shape != (3,) or not np.all(np.isfinite(xyz)):
            raise ProbeError(f"probe '{name}': coordinates must be three finite numbers, "
                             f"got {c!r}")
        out[str(name)] = xyz
    return out


def locate_probes(modes_path: str | os.PathLike, coords: np.ndarray,
                  names: Sequence[str] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Containing hexahedron and reference coordinates of each probe.

    Parameters
    ----------
    modes_path
        ``modes.h5`` (its ``/mesh``).
    coords
        (p, 3) probe coordinates [m].
    names
        Probe names for error messages.

    Returns
    -------
    elem : ndarray (p,)
    xi : ndarray (p, 3)

    Raises
    ------
    ProbeError
        When a point lies outside every hexahedron.
    """
    import h5py

    coords = np.asarray(coords, dtype=float).reshape(-1, 3)
    with h5py.File(modes_path, "r") as f:
        mesh = _search_mesh(f)
    if len(coords) == 0:
        return np.zeros(0, np.int64), np.zeros((0, 3))
    elem, xi = locate(coords, mesh)
    bad = np.flatnonzero(elem < 0)
    if bad.size:
        names = list(names) if names is not None else [f"#{i}" for i in range(len(coords))]
        where = ", ".join(f"'{names[i]}' at {tuple(float(v) for v in coords[i])}" for i in bad)
        raise ProbeError(f"probe point(s) outside the hexahedral mesh of {modes_path}: {where}")
    return elem, np.clip(xi, -1.0, 1.0)


def interpolate_basis(path: str | os.PathLike, dataset: str, conn: np.ndarray,
                      weights: np.ndarray, rows: int) -> np.ndarray:
    """Interpolate the first ``rows`` shapes of a (r, n, 3) dataset at probe points.

    Parameters
    ----------
    path, dataset
        HDF5 file and dataset, e.g. ``modes.h5`` and ``modes/translation``.
    conn
        (p, 8) nodes of each probe's element.
    weights
        (p, 8) shape-function values at each probe.
    rows
        Number of leading shapes (modes) to use.

    Returns
    -------
    ndarray, shape (p, rows, 3)
    """
    import h5py

    nodes, inverse = np.unique(conn, return_inverse=True)   # h5py wants increasing indices
    with h5py.File(path, "r") as f:
        ds = f[dataset]
        if ds.ndim != 3 or ds.shape[2] != 3 or ds.shape[0] < rows:
            raise ValueError(f"{path}:{dataset} has shape {ds.shape}, need ({rows}+, n, 3)")
        vals = ds[:rows, nodes, :] if len(nodes) else np.zeros((rows, 0, 3))
    local = vals[:, inverse.reshape(conn.shape), :]            # (rows, p, 8, 3)
    return np.einsum("rpai,pa->pri", local, weights)


def probe_modes(modes_path: str | os.PathLike, coords: np.ndarray, m: int,
                names: Sequence[str] | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mode shapes interpolated at probe points (rank 0, serial).

    Parameters
    ----------
    modes_path
        A complete ``modes.h5``.
    coords
        (p, 3) probe coordinates.
    m
        Number of leading modes.
    names
        Probe names (error messages).

    Returns
    -------
    phi : ndarray, shape (p, m, 3)
        ``phi[i]`` maps modal coordinates to the displacement of probe ``i``:
        ``u_i(t) = q(t) @ phi[i]``.
    elem : ndarray, shape (p,)
        Containing hexahedra.
    xi : ndarray, shape (p, 3)
        Reference coordinates in them.
    """
    elem, xi = locate_probes(modes_path, coords, names)
    import h5py

    with h5py.File(modes_path, "r") as f:
        conn = f["mesh/hexes"][()][elem] if len(elem) else np.zeros((0, 8), np.int64)
    phi = interpolate_basis(modes_path, "modes/translation", conn, hex_shape_values(xi), m)
    return phi, elem, xi


def probe_histories(modes_path: str | os.PathLike, t: np.ndarray, q: np.ndarray,
                    q_dot: np.ndarray, q_ddot: np.ndarray, *, user_probes: UserProbes = (),
                    user_roles: Mapping[str, str] | None = None, mesh: bool = True,
                    extra: Sequence[ExtraBasis] | None = None
                    ) -> dict[str, dict[str, np.ndarray]]:
    """Displacement, velocity and acceleration histories at the probe points.

    Parameters
    ----------
    modes_path
        A complete ``modes.h5``; the first ``m = q.shape[1]`` modes are used.
    t
        (nt,) times.
    q, q_dot, q_ddot
        (nt, m) modal histories.
    user_probes
        Extra probe points, ``{name: xyz}`` or a list of ``xyz``.
    user_roles
        Roles of the user probes by name (:data:`railvib_hpc.schema.PROBE_ROLES`; missing:
        ``"ground"``).
    mesh
        Include the named probes of ``/mesh/probes`` (with their stored roles).
    extra
        Additional bases ``(h5 file, dataset, g, g_dot, g_ddot)`` added like extra modes.

    Returns
    -------
    dict
        ``name -> {"t", "displacement", "velocity", "acceleration", "coords", "element",
        "xi", "role"}`` with (nt, 3) histories.

    Raises
    ------
    ProbeError
        For a user probe named like a mesh probe or with an unknown role, and for a
        ``modes.h5`` written before probes had roles.
    """
    import h5py

    probes = mesh_probes(modes_path) if mesh else {}
    roles: dict[str, str] = {}
    if probes:
        stored = mesh_probe_roles(modes_path)
        if stored is None:
            raise ProbeError(f"{modes_path} stores no probe roles (written by an older "
                             "version): rerun 'railvib modal' (it recomputes the file)")
        roles.update(stored)
    user_roles = dict(user_roles or {})
    for name, xyz in user_probe_dict(user_probes).items():
        if name in probes:
            raise ProbeError(f"user probe '{name}' has the name of a probe of the mesh")
        probes[name] = xyz
        roles[name] = user_roles.get(name, DEFAULT_PROBE_ROLE)
        if roles[name] not in PROBE_ROLES:
            raise ProbeError(f"probe '{name}': role {roles[name]!r} is not one of "
                             + ", ".join(PROBE_ROLES))
    names = list(probes)
    if not names:
        return {}
    coords = np.array([probes[k] for k in names])
    t = np.asarray(t, dtype=float)
    hist = [np.asarray(a, dtype=float) for a in (q, q_dot, q_ddot)]
    m = hist[0].shape[1]
    elem, xi = locate_probes(modes_path, coords, names)
    with h5py.File(modes_path, "r") as f:
        conn = f["mesh/hexes"][()][elem]
    weights = hex_shape_values(xi)
    phi = [interpolate_basis(modes_path, "modes/translation", conn, weights, m)]
    for e in extra or []:
        g = [np.asarray(a, dtype=float) for a in e[2:5]]
        phi.append(interpolate_basis(e[0], e[1], conn, weights, g[0].shape[1]))
        hist = [np.hstack([h, gi]) for h, gi in zip(hist, g)]
    basis = np.concatenate(phi, axis=1)                           # (p, M, 3)
    out = {}
    for i, name in enumerate(names):
        u, v, a = (h @ basis[i] for h in hist)
        out[name] = {"t": t, "displacement": u, "velocity": v, "acceleration": a,
                     "coords": coords[i], "element": np.int64(elem[i]), "xi": xi[i],
                     "role": roles[name]}
    return out


def probe_peaks(history: Mapping[str, np.ndarray], wave_threshold: float) -> dict[str, Any]:
    """Peak response of one probe history (``t``, ``displacement``, ``velocity``,
    ``acceleration``, ``coords``), as the studies and the Python API report it.

    Returns
    -------
    dict
        ``coords`` [m]; ``t_onset`` (first time ``|a|`` reaches ``wave_threshold`` times its
        peak, None if never); ``acc_x``, ``acc_y``, ``acc_vertical`` (peak ``|a_x|``,
        ``|a_y|``, ``|a_z|``) and ``acc_total`` (peak ``|a|``) [m/s²] with ``t_acc_total``
        [s]; ``vel_total`` (peak ``|v|``) [m/s]; ``disp_total`` (peak ``|u|``) [m].

    Examples
    --------
    >>> t = np.linspace(0.0, 1.0, 5)
    >>> a = np.zeros((5, 3)); a[2] = [0.0, 3.0, -4.0]
    >>> h = {"t": t, "acceleration": a, "velocity": a / 10, "displacement": a / 100,
    ...      "coords": np.zeros(3)}
    >>> p = probe_peaks(h, 0.1)
    >>> p["acc_vertical"], p["acc_total"], p["t_acc_total"], p["t_onset"]
    (4.0, 5.0, 0.5, 0.5)
    """
    t = np.asarray(history["t"], dtype=float)
    a, v, u = (np.asarray(history[k], dtype=float)
               for k in ("acceleration", "velocity", "displacement"))
    amag = np.linalg.norm(a, axis=1)
    k = int(np.argmax(amag)) if amag.size else 0
    onset = np.flatnonzero(amag >= wave_threshold * amag[k]) if amag.size else np.array([])
    return {"coords": np.asarray(history["coords"], dtype=float).tolist(),
            "t_onset": float(t[onset[0]]) if onset.size else None,
            "acc_x": float(np.abs(a[:, 0]).max()) if a.size else 0.0,
            "acc_y": float(np.abs(a[:, 1]).max()) if a.size else 0.0,
            "acc_vertical": float(np.abs(a[:, 2]).max()) if a.size else 0.0,
            "acc_total": float(amag[k]) if amag.size else 0.0,
            "t_acc_total": float(t[k]) if t.size else 0.0,
            "vel_total": float(np.linalg.norm(v, axis=1).max()) if v.size else 0.0,
            "disp_total": float(np.linalg.norm(u, axis=1).max()) if u.size else 0.0}
