"""``modes.h5`` + ``modes.xdmf``: layout, writer, readers and check (written in parallel).

Layout of ``modes.h5``::

    /modes/frequency_hz    (m,)            ascending
    /modes/eigenvalue      (m,)            omega^2 [rad^2/s^2]
    /modes/strain_energy   (m, g)          per material group (summing to omega^2)
    /modes/translation     (m, n, 3)       ux uy uz of every node (0 where constrained)
    /modes/rotation        (m, nr, 3)      rx ry rz of the beam nodes /mesh/rotation_nodes
    /mesh/points (n, 3), /mesh/node_ids (n,), /mesh/hexes, /mesh/hex_part, /mesh/lines,
    /mesh/line_part, /mesh/node_sets/*, /mesh/probes/*   as in mesh.h5 (probes/roles too)
    /mesh/rotation_nodes   (nr,)           nodes that carry rotations (rails, sleepers)
    /mesh/rail_nodes       (r, k)          flexible-rail nodes of each rail (2 per track, by
                                           increasing y), sorted along x
    /mesh/nodal_mass       (n,)            lumped translational mass per node [kg]
    /dofs/index            (n, 6)          global DOF number of each component, -1 if fixed
    /pads/nodes (p, 2), /pads/direction (p,), /pads/stiffness (p,), /pads/damping (p,)
                                           rail-pad spring-dampers (rail node, sleeper node;
                                           0 = x, 1 = y, 2 = z; N/m; N s/m), kept for the
                                           dynamic stage (their damping is not in K or M)
    attrs: the provenance of :func:`railvib_hpc.io.provenance.provenance` (inputs_sha256,
           upstream_sha256, case_toml, format_version, ...), complete, petsc_version,
           slepc_version, stats (JSON), n_modes, n_dofs

With more than one rank and an MPI-enabled h5py, every rank writes its own
node slice collectively (``driver="mpio"``); otherwise slices are gathered to
rank 0. The file is written by :func:`railvib_hpc.io.atomic.write_h5`
(temporary name, space reserved, ``complete`` set last, renamed, recorded): an
interrupted run never leaves a file that looks complete. ``modes.xdmf`` (rank 0,
written after the rename, with its sidecar of per-step views ``modes_views.h5``, see
:mod:`railvib_hpc.io.xdmf`) animates the mode shapes in ParaView: one time step per mode.

Check: :func:`check_modes` (eigenvalues, shapes, masses; with ``full`` every mode shape),
with :func:`check_eigenvalues` and :func:`check_mode_shapes` for the arrays in memory.
Plausibility bounds (named factors, each with its derivation):

* Mass-normalised modes, ``phi^T M phi = 1``: for a lumped node mass ``m_i`` the
  translation obeys ``m_i |phi_i|^2 <= 1 / c`` where ``c`` is the smallest eigenvalue of
  an element's consistent mass matrix relative to its lumped one: ``1/3`` for linear
  1-D elements, ``1/27`` for the trilinear hexahedron (tensor product). Hence
  ``sqrt(m_i) |phi_i| <= sqrt(27) = 5.2``; :data:`MODE_SHAPE_BOUND` = 6. (The coarse
  thesis model reaches 0.06.)
* Rotations are displacement gradients: ``|theta| <= ROTATION_FACTOR max|u| / h_min``
  with ``h_min`` the shortest line element (:data:`ROTATION_FACTOR` = 100).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...schema import PART_ID
from ..atomic import write_h5
from ..parallel_h5 import h5py_parallel_ok
from ..xdmf import H5Array, Series, hex_mesh, write_series
from .checks import absent, exceeds, h5_read, nonfinite

if TYPE_CHECKING:      # io sits below mesh in the layer order: the mesh is only read here
    from mpi4py import MPI

    from ...mesh.model import Mesh


def write_modes(path: Path, comm: MPI.Comm, mesh: Mesh, node_range: slice, eigenvalues: np.ndarray,
                translation: np.ndarray, rotation: np.ndarray, rotation_nodes: np.ndarray,
                rot_range: slice, nodal_mass: np.ndarray, dof_index: np.ndarray,
                attrs: dict[str, object], pads: dict[str, np.ndarray] | None = None,
                energies: dict[str, np.ndarray] | None = None) -> str:
    """Write ``modes.h5`` (collective: every rank calls it with its own slices); returns its
    content digest.

    Parameters
    ----------
    node_range
        Nodes owned by this rank (contiguous).
    translation
        (m, owned nodes, 3) of this rank.
    rotation
        (m, owned rotation nodes, 3) of this rank; ``rot_range`` their positions in
        ``rotation_nodes``.
    nodal_mass
        Masses of the owned nodes.
    pads
        ``nodes``, ``direction``, ``stiffness``, ``damping`` arrays of the rail pads.
    energies
        Strain energy of every mode per material group, (m,) each, identical on every rank
        (``/modes/strain_energy`` (m, groups), attribute ``groups``).
    """

    n, m = mesh.n_nodes, len(eigenvalues)
    # attributes are written collectively: every rank must pass the same values (the
    # stats hold per-rank timings, so rank 0's are taken; unequal strings corrupt them)
    attrs = comm.bcast(dict(attrs), root=0)
    parallel = h5py_parallel_ok(comm)
    if not parallel and comm.size > 1:
        parts = comm.gather((node_range, translation, rot_range, rotation, nodal_mass), root=0)
        if comm.rank == 0:
            translation = np.concatenate([p[1] for p in parts], axis=1)
            rotation = np.concatenate([p[3] for p in parts], axis=1)
            nodal_mass = np.concatenate([p[4] for p in parts])
            node_range, rot_range = slice(0, n), slice(0, len(rotation_nodes))

    def fill(f, par: bool) -> None:
        _write(f, comm.rank == 0 or not par, mesh, m, n, eigenvalues, translation, rotation,
               rotation_nodes, node_range, rot_range, nodal_mass, dof_index, attrs, pads or {},
               energies or {})

    nr = len(rotation_nodes)
    values = (m * (n + nr) * 3                          # translation, rotation
              + n * (3 + 1 + 1 + 6)                     # points, node ids, masses, DOF index
              + mesh.hexes.size + mesh.lines.size + nr + mesh.rail_nodes().size
              + sum(np.asarray(v).size for v in mesh.node_sets.values())
              + m * (2 + len(energies or {})))          # frequencies, eigenvalues, energies
    size = 8 * values + mesh.hex_part.nbytes + mesh.line_part.nbytes \
        + sum(np.asarray(v).nbytes for v in (pads or {}).values())
    sha = write_h5(path, comm, fill, size_hint=int(size), attrs=attrs, parallel=parallel,
                   check=lambda tmp: check_modes(tmp, False))
    if comm.rank == 0:
        write_modes_xdmf(path)
    comm.Barrier()
    return sha


def _write(f, root: bool, mesh: Mesh, m: int, n: int, eigenvalues, translation, rotation,
           rotation_nodes, node_range, rot_range, nodal_mass, dof_index, attrs, pads,
           energies) -> None:
    # dataset creation is collective: identical calls on every rank
    g = f.create_group("modes")
    d_f = g.create_dataset("frequency_hz", (m,), "f8")
    if energies:
        d_e = g.create_dataset("strain_energy", (m, len(energies)), "f8")
        d_e.attrs["groups"] = json.dumps(list(energies))
    d_l = g.create_dataset("eigenvalue", (m,), "f8")
    d_t = g.create_dataset("translation", (m, n, 3), "f8")
    d_r = g.create_dataset("rotation", (m, len(rotation_nodes), 3), "f8")
    gm = f.create_group("mesh")
    rails = mesh.rail_nodes()
    names = list(mesh.probes)
    coords = np.array([mesh.probes[k] for k in names], dtype=float).reshape(-1, 3)
    mesh_data = {
        "points": mesh.points, "node_ids": np.arange(n, dtype=np.int64), "hexes": mesh.hexes,
        "hex_part": mesh.hex_part, "lines": mesh.lines, "line_part": mesh.line_part,
        "rotation_nodes": rotation_nodes, "rail_nodes": rails,
    }
    dsets = {k: gm.create_dataset(k, v.shape, v.dtype) for k, v in mesh_data.items()}
    d_mass = gm.create_dataset("nodal_mass", (n,), "f8")
    ns = gm.create_group("node_sets")
    ns_sets = {k: ns.create_dataset(k, v.shape, v.dtype) for k, v in mesh.node_sets.items()}
    pr = gm.create_group("probes")
    # fixed-length ASCII: parallel HDF5 cannot write variable-length strings
    d_pn = pr.create_dataset("names", (len(names),), "S64")
    d_pc = pr.create_dataset("coords", coords.shape, "f8")
    d_pr = pr.create_dataset("roles", (len(names),), "S16")
    d_dof = f.create_group("dofs").create_dataset("index", dof_index.shape, dof_index.dtype)
    gp = f.create_group("pads")
    d_pads = {k: gp.create_dataset(k, v.shape, v.dtype) for k, v in pads.items()}
    for k, v in attrs.items():
        f.attrs[k] = v
    f.attrs["part_names"] = json.dumps({v: k for k, v in PART_ID.items()})
    f.attrs["n_modes"] = m
    f.attrs["complete"] = 0
    # data: shared arrays from rank 0, slices from their owners
    if root:
        if energies:
            d_e[...] = np.stack([np.asarray(v, dtype=float) for v in energies.values()], axis=1)
        d_f[:] = np.sqrt(np.maximum(eigenvalues, 0.0)) / (2 * np.pi)
        d_l[:] = eigenvalues
        for k, v in mesh_data.items():
            dsets[k][...] = v
        for k, v in mesh.node_sets.items():
            ns_sets[k][...] = v
        d_pn[:] = np.array(names, dtype="S64")
        d_pc[...] = coords
        d_pr[:] = np.array([mesh.probe_roles.get(k, "") for k in names], dtype="S16")
        d_dof[...] = dof_index
        for k, v in pads.items():
            d_pads[k][...] = v
    if node_range.stop > node_range.start:
        d_t[:, node_range, :] = translation
        d_mass[node_range] = nodal_mass
    if rot_range.stop > rot_range.start:
        d_r[:, rot_range, :] = rotation


def write_modes_xdmf(path: Path) -> Path:
    """Write ``modes.xdmf`` (+ ``modes_views.h5``) for the modes file ``path``: time step k
    shows mode k (serial; returns the XDMF path).

    The grid of mode k is named ``mode_<k>_<frequency>Hz``; its node vector
    ``mode_shape`` is row k - 1 of ``/modes/translation`` (:mod:`railvib_hpc.io.xdmf`).
    """
    import h5py

    path = Path(path)
    with h5py.File(path, "r") as f:
        points, block = hex_mesh(f)
        shapes = H5Array.of(f, "/modes/translation")
        freq = f["modes/frequency_hz"][()]
    xdmf = path.with_suffix(".xdmf")
    write_series(xdmf, points, block, np.arange(1, len(freq) + 1),
                 [Series("mode_shape", shapes, "Node")],
                 [f"mode_{k + 1}_{fk:.4f}Hz" for k, fk in enumerate(freq)])
    return xdmf


def read_modes_summary(path: Path) -> dict | None:
    """Return the attributes of a complete ``modes.h5``, or None if missing/incomplete/corrupt."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if int(f.attrs.get("complete", 0)) != 1:
                return None
            out = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
            out["frequency_hz"] = f["modes/frequency_hz"][()]
            return out
    except (OSError, KeyError):
        return None


def has_probe_roles(path: Path) -> bool:
    """True when ``modes.h5`` stores the roles of its named probes (written since roles
    exist); the modal stage recomputes older files."""
    import h5py

    with h5py.File(path, "r") as f:
        return "mesh/probes/roles" in f or "mesh/probes/names" not in f


def read_strain_energies(path: Path) -> dict[str, np.ndarray] | None:
    """``/modes/strain_energy`` of ``modes.h5`` as {group: (m,)}; None when the file has none
    (written before the per-material energies existed)."""
    import h5py

    with h5py.File(path, "r") as f:
        if "modes/strain_energy" not in f:
            return None
        d = f["modes/strain_energy"]
        groups = json.loads(d.attrs["groups"])
        e = d[()]
    return {g: e[:, j] for j, g in enumerate(groups)}


#: Bound of ``sqrt(m_i) |phi_i|`` for mass-normalised modes (sqrt(27) rounded up).
MODE_SHAPE_BOUND = 6.0

#: Rotations vs displacement gradient ``max|u| / h_min``.
ROTATION_FACTOR = 100.0

#: Modes per block when streaming ``modes/translation``.
_MODES_PER_BLOCK = 8


def check_eigenvalues(eigenvalues: np.ndarray) -> list[str]:
    """Finite, positive, ascending (to round-off) eigenvalues."""
    lam = np.asarray(eigenvalues, dtype=float)
    out = nonfinite("modes/eigenvalue", lam)
    if out:
        return out
    if lam.size == 0:
        return ["modes/eigenvalue is empty"]
    if np.any(lam <= 0):
        out.append(f"modes/eigenvalue has {int(np.sum(lam <= 0))} values <= 0 (the model "
                   "must be supported: no rigid-body modes)")
    if np.any(np.diff(lam) < -1e-8 * np.abs(lam[1:])):
        out.append("modes/eigenvalue is not ascending")
    return out


def mode_bounds(nodal_mass: np.ndarray) -> np.ndarray:
    """Bound of ``|phi_i|`` per node from the mass normalisation (module notes)."""
    m = np.asarray(nodal_mass, dtype=float)
    floor = float(m[m > 0].min()) if np.any(m > 0) else 1.0
    return MODE_SHAPE_BOUND / np.sqrt(np.where(m > 0, m, floor))


def check_mode_shapes(translation: np.ndarray, nodal_mass: np.ndarray, first: int = 0
                      ) -> list[str]:
    """Finite, mass-normalisation-bounded translations (m, n, 3) of modes ``first..``."""
    out = nonfinite(f"modes/translation (modes {first + 1}..)", translation)
    if out:
        return out
    mag = np.linalg.norm(translation, axis=2)
    return exceeds(f"modes/translation (modes {first + 1}..)", mag,
                   mode_bounds(nodal_mass)[None, :], "mass normalisation")


def check_modes(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                ) -> list[str]:
    """``modes.h5``: eigenvalues, shapes, masses; with ``full`` every mode shape."""
    with h5_read(path) as f:
        missing = absent(f, ("modes/eigenvalue", "modes/frequency_hz", "modes/translation",
                            "modes/rotation", "mesh/points", "mesh/nodal_mass",
                            "mesh/rail_nodes", "mesh/rotation_nodes", "dofs/index"))
        if missing:
            return missing
        lam = f["modes/eigenvalue"][()]
        out = check_eigenvalues(lam)
        n = f["mesh/points"].shape[0]
        tr, rot = f["modes/translation"], f["modes/rotation"]
        nr = f["mesh/rotation_nodes"].shape[0]
        if tr.shape != (len(lam), n, 3):
            out.append(f"modes/translation has shape {tr.shape}, expected ({len(lam)}, {n}, 3)")
        if rot.shape != (len(lam), nr, 3):
            out.append(f"modes/rotation has shape {rot.shape}, expected ({len(lam)}, {nr}, 3)")
        mass = f["mesh/nodal_mass"][()]
        out += nonfinite("mesh/nodal_mass", mass)
        if mass.shape != (n,) or np.any(mass < 0):
            out.append("mesh/nodal_mass must be (n,) and >= 0")
        freq = f["modes/frequency_hz"][()]
        if freq.shape == lam.shape and not out and not np.allclose(
                freq, np.sqrt(np.maximum(lam, 0)) / (2 * np.pi), rtol=1e-9):
            out.append("modes/frequency_hz does not match modes/eigenvalue")
        if out or not full:
            return out
        h_min = _shortest_line(f)
        umax = 0.0
        for k in range(0, len(lam), _MODES_PER_BLOCK):
            block = tr[k:k + _MODES_PER_BLOCK]
            out += check_mode_shapes(block, mass, k)
            if out:
                return out
            umax = max(umax, float(np.abs(block).max()) if block.size else 0.0)
        r = rot[()]
        out += nonfinite("modes/rotation", r)
        if not out and h_min > 0:
            out += exceeds("modes/rotation", r, ROTATION_FACTOR * umax / h_min,
                           "displacement gradient")
    return out


def _shortest_line(f) -> float:
    if "mesh/lines" not in f or f["mesh/lines"].shape[0] == 0:
        return 0.0
    pts, lines = f["mesh/points"][()], f["mesh/lines"][()]
    length = np.linalg.norm(pts[lines[:, 1]] - pts[lines[:, 0]], axis=1)
    length = length[length > 0]
    return float(length.min()) if length.size else 0.0
