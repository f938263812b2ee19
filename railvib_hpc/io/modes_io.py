"""``modes.h5`` + ``modes.xdmf``: mass-normalised modes written in parallel.

Layout of ``modes.h5``::

    /modes/frequency_hz    (m,)            ascending
    /modes/eigenvalue      (m,)            omega^2 [rad^2/s^2]
    /modes/translation     (m, n, 3)       ux uy uz of every node (0 where constrained)
    /modes/rotation        (m, nr, 3)      rx ry rz of the beam nodes /mesh/rotation_nodes
    /mesh/points (n, 3), /mesh/node_ids (n,), /mesh/hexes, /mesh/hex_part, /mesh/lines,
    /mesh/line_part, /mesh/node_sets/*, /mesh/probes/*   as in mesh.h5
    /mesh/rotation_nodes   (nr,)           nodes that carry rotations (rails, sleepers)
    /mesh/rail_nodes       (2, k)          flexible-rail nodes of each rail, sorted along x
    /mesh/nodal_mass       (n,)            lumped translational mass per node [kg]
    /dofs/index            (n, 6)          global DOF number of each component, -1 if fixed
    /pads/nodes (p, 2), /pads/direction (p,), /pads/stiffness (p,), /pads/damping (p,)
                                           rail-pad spring-dampers (rail node, sleeper node;
                                           0 = x, 1 = y, 2 = z; N/m; N s/m), kept for the
                                           dynamic stage (their damping is not in K or M)
    attrs: the provenance of :func:`railvib_hpc.io.stage_files.provenance` (inputs_sha256,
           upstream_sha256, case_toml, format_version, ...), complete, petsc_version,
           slepc_version, stats (JSON), n_modes, n_dofs

With more than one rank and an MPI-enabled h5py, every rank writes its own
node slice collectively (``driver="mpio"``); otherwise slices are gathered to
rank 0. The file is written by :func:`railvib_hpc.io.stage_files.write_h5`
(temporary name, space reserved, ``complete`` set last, renamed, recorded): an
interrupted run never leaves a file that looks complete. ``modes.xdmf`` (rank 0,
written after the rename) animates the mode shapes in ParaView: one time step per mode.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..mesh.model import Mesh
from ..schema import PART_ID
from .parallel_h5 import h5py_parallel_ok
from .stage_checks import check_modes
from .stage_files import write_h5, write_text
from .xdmf import temporal_xdmf


def rail_nodes(mesh: Mesh) -> np.ndarray:
    """Flexible-rail nodes, shape (2, k): rail at negative y first, each sorted along x."""
    nodes = np.unique(mesh.lines[mesh.line_part == PART_ID["rail"]])
    y = mesh.points[nodes, 1]
    out = []
    for side in (y < 0, y >= 0):
        n = nodes[side]
        out.append(n[np.argsort(mesh.points[n, 0], kind="stable")])
    if len(out[0]) != len(out[1]):
        width = max(len(out[0]), len(out[1]))
        out = [np.pad(o, (0, width - len(o)), constant_values=-1) for o in out]
    return np.array(out, dtype=np.int64)


def n_rail_nodes(mesh: Mesh) -> int:
    """Flexible-rail nodes per rail (an upper bound: all rail nodes)."""
    return int(np.unique(mesh.lines[mesh.line_part == PART_ID["rail"]]).size)


def write_modes(path: Path, comm, mesh: Mesh, node_range: slice, eigenvalues: np.ndarray,
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
              + mesh.hexes.size + mesh.lines.size + nr + 2 * n_rail_nodes(mesh)
              + sum(np.asarray(v).size for v in mesh.node_sets.values())
              + m * (2 + len(energies or {})))          # frequencies, eigenvalues, energies
    size = 8 * values + mesh.hex_part.nbytes + mesh.line_part.nbytes \
        + sum(np.asarray(v).nbytes for v in (pads or {}).values())
    sha = write_h5(path, comm, fill, size_hint=int(size), attrs=attrs, parallel=parallel,
                   check=lambda tmp: check_modes(tmp, False))
    if comm.rank == 0:
        write_text(path.with_suffix(".xdmf"), modes_xdmf(path.name, mesh, eigenvalues))
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
    rails = rail_nodes(mesh)
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
        d_dof[...] = dof_index
        for k, v in pads.items():
            d_pads[k][...] = v
    if node_range.stop > node_range.start:
        d_t[:, node_range, :] = translation
        d_mass[node_range] = nodal_mass
    if rot_range.stop > rot_range.start:
        d_r[:, rot_range, :] = rotation


def modes_xdmf(h5_name: str, mesh: Mesh, eigenvalues: np.ndarray) -> str:
    """XDMF temporal collection: time step k shows mode k (its frequency in the grid name)."""
    n, ne, m = mesh.n_nodes, len(mesh.hexes), len(eigenvalues)
    freq = np.sqrt(np.maximum(eigenvalues, 0.0)) / (2 * np.pi)
    topo = (f'<Topology TopologyType="Hexahedron" NumberOfElements="{ne}"><DataItem '
            f'Dimensions="{ne} 8" NumberType="Int" Precision="8" Format="HDF">{h5_name}:'
            f'/mesh/hexes</DataItem></Topology>')
    geo = (f'<Geometry GeometryType="XYZ"><DataItem Dimensions="{n} 3" NumberType="Float" '
           f'Precision="8" Format="HDF">{h5_name}:/mesh/points</DataItem></Geometry>')
    part = (f'<Attribute Name="part_id" AttributeType="Scalar" Center="Cell"><DataItem '
            f'Dimensions="{ne}" NumberType="Int" Precision="4" Format="HDF">{h5_name}:'
            f'/mesh/hex_part</DataItem></Attribute>')
    steps = []
    for k in range(m):
        steps.append(f"""      <Grid Name="mode_{k + 1}_{freq[k]:.4f}Hz" GridType="Uniform">
        <Time Value="{k + 1}"/>
        {topo}
        {geo}
        {part}
        <Attribute Name="mode_shape" AttributeType="Vector" Center="Node">
          <DataItem ItemType="HyperSlab" Dimensions="{n} 3" Type="HyperSlab">
            <DataItem Dimensions="3 3" Format="XML">{k} 0 0 1 1 1 1 {n} 3</DataItem>
            <DataItem Dimensions="{m} {n} 3" NumberType="Float" Precision="8" Format="HDF">{h5_name}:/modes/translation</DataItem>
          </DataItem>
        </Attribute>
      </Grid>""")  # noqa: E501
    return temporal_xdmf("modes", steps)


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
