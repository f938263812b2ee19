"""``mesh.h5`` + ``mesh.xdmf``: layout, writer, reader and check (the mesh stage's model).

Layout of ``mesh.h5``::

    /mesh/points            (n, 3) float64   node coordinates [m]
    /mesh/hexes             (ne, 8) int64    8-node hexahedra (VTK order)
    /mesh/hex_part          (ne,) int32      part id of each hex
    /mesh/lines             (nl, 2) int64    beams and spring-dampers
    /mesh/line_part         (nl,) int32      part id of each line element
    /mesh/node_sets/<name>  (k,) int64       bottom, x_faces, y_faces
    /mesh/probes/names      (p,) str         named probe points
    /mesh/probes/coords     (p, 3) float64
    /mesh/probes/nearest_node (p,) int64
    /mesh/probes/roles      (p,) str         role of each probe (schema.PROBE_ROLES)
    attrs: part_names (JSON {id: name}) and the provenance of
           :func:`railvib_hpc.io.provenance.provenance` (inputs_sha256, case_toml, ...)

The XDMF file (:mod:`railvib_hpc.io.xdmf`) holds two grids sharing the points: ``solids``
(Hexahedron) and ``beams_and_pads`` (Polyline, 2 nodes), each with ``part_id`` as cell
data.

Writer: :func:`write_mesh_files` (:func:`write_mesh_h5`, then :func:`mesh_xdmf`); it takes
the mesh model (:class:`railvib_hpc.mesh.model.Mesh`, a layer above this one) duck-typed.
Reader: :func:`read_mesh_arrays` (the arrays and attributes;
:func:`railvib_hpc.mesh.mesh_io.read_mesh_h5` builds the mesh model of them). Check:
:func:`check_mesh` (on write and on reuse), :func:`check_mesh_arrays` (the arrays in
memory).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ...schema import PART_ID
from ..atomic import write_h5, write_text
from ..files import MESH_H5, MESH_XDMF
from ..xdmf import CellBlock, H5Array, mesh_document
from .checks import absent, h5_read, nonfinite

if TYPE_CHECKING:      # io sits below mesh in the layer order: the mesh is only read here
    from ...mesh.model import Mesh


def inverted_hexes(points: np.ndarray, hexes: np.ndarray) -> int:
    """Number of hexahedra (VTK order) with a non-positive corner Jacobian (inverted or
    garbled; a valid mesh has none: the mesh stage refuses inverted elements). Batched over
    the elements (:func:`~railvib_hpc.fem.reference.element_batches`)."""
    from ...fem.reference import element_batches, hex_corner_determinants

    points, hexes = np.asarray(points), np.asarray(hexes)
    bad = 0
    for s in element_batches(len(hexes)):
        det = hex_corner_determinants(points[hexes[s]])
        bad += int(np.count_nonzero(~(det.min(axis=1) > 0)))
    return bad


def check_mesh_arrays(points, hexes, hex_part, lines, line_part, node_sets=None) -> list[str]:
    """Mesh arrays: finite coordinates, connectivity within the nodes, known part ids, no
    inverted hexahedra."""
    from ...schema import PART_ID

    n = len(points)
    out = nonfinite("mesh/points", np.asarray(points))
    if np.ndim(points) != 2 or np.shape(points)[1:] != (3,):
        out.append(f"mesh/points has shape {np.shape(points)}, expected (n, 3)")
    for name, conn, width in (("mesh/hexes", hexes, 8), ("mesh/lines", lines, 2)):
        conn = np.asarray(conn)
        if conn.ndim != 2 or conn.shape[1] != width:
            out.append(f"{name} has shape {conn.shape}, expected (k, {width})")
        elif conn.size and (conn.min() < 0 or conn.max() >= n):
            out.append(f"{name} refers to nodes outside 0..{n - 1}")
    ids = set(PART_ID.values())
    for name, part, conn in (("mesh/hex_part", hex_part, hexes), ("mesh/line_part", line_part,
                                                                   lines)):
        part = np.asarray(part)
        if part.shape != (len(conn),):
            out.append(f"{name} has shape {part.shape}, expected ({len(conn)},)")
        elif part.size and not set(np.unique(part).tolist()) <= ids:
            out.append(f"{name} has unknown part ids")
    for name, nodes in (node_sets or {}).items():
        nodes = np.asarray(nodes)
        if nodes.size and (nodes.min() < 0 or nodes.max() >= n):
            out.append(f"mesh/node_sets/{name} refers to nodes outside 0..{n - 1}")
    if not out:
        bad = inverted_hexes(points, hexes)
        if bad:
            out.append(f"mesh/hexes has {bad} inverted or degenerate hexahedra")
    return out


def check_mesh(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
               ) -> list[str]:
    """``mesh.h5`` (small: always read completely)."""
    with h5_read(path) as f:
        missing = absent(f, ("mesh/points", "mesh/hexes", "mesh/hex_part", "mesh/lines",
                            "mesh/line_part", "mesh/probes/coords"))
        if missing:
            return missing
        g = f["mesh"]
        sets = {k: v[()] for k, v in g["node_sets"].items()} if "node_sets" in g else {}
        return check_mesh_arrays(g["points"][()], g["hexes"][()], g["hex_part"][()],
                                 g["lines"][()], g["line_part"][()], sets) \
            + nonfinite("mesh/probes/coords", g["probes/coords"][()])


def mesh_nbytes(mesh: Mesh) -> int:
    """Predicted size of ``mesh.h5`` [bytes] (its arrays)."""
    sets = sum(np.asarray(v).nbytes for v in mesh.node_sets.values())
    return int(mesh.points.nbytes + mesh.hexes.nbytes + mesh.hex_part.nbytes + mesh.lines.nbytes
               + mesh.line_part.nbytes + sets + 128 * len(mesh.probes))


def write_mesh_h5(path: Path, mesh: Mesh, attrs: dict[str, str]) -> str:
    """Write ``mesh.h5`` atomically, checked and recorded (serial, rank 0); returns its
    content digest."""
    import h5py

    def fill(f, parallel: bool) -> None:
        g = f.create_group("mesh")
        g.create_dataset("points", data=mesh.points)
        g.create_dataset("hexes", data=mesh.hexes)
        g.create_dataset("hex_part", data=mesh.hex_part)
        g.create_dataset("lines", data=mesh.lines)
        g.create_dataset("line_part", data=mesh.line_part)
        ns = g.create_group("node_sets")
        for name, nodes in mesh.node_sets.items():
            ns.create_dataset(name, data=nodes)
        pr = g.create_group("probes")
        names = list(mesh.probes)
        pr.create_dataset("names", data=np.array(names, dtype=h5py.string_dtype()))
        coords = np.array([mesh.probes[n] for n in names], dtype=float).reshape(-1, 3)
        pr.create_dataset("coords", data=coords)
        pr.create_dataset("roles", data=np.array([mesh.probe_roles.get(n, "") for n in names],
                                                 dtype=h5py.string_dtype()))
        pr.create_dataset("nearest_node",
                          data=mesh.nearest_nodes(coords))
        f.attrs["part_names"] = json.dumps({v: k for k, v in PART_ID.items()})

    return write_h5(path, None, fill, size_hint=mesh_nbytes(mesh), attrs=attrs,
                    check=check_mesh)


def read_mesh_arrays(path: Path) -> tuple[dict[str, Any], dict]:
    """Read ``mesh.h5``: the mesh model's fields (``points``, ``hexes``, ``hex_part``,
    ``lines``, ``line_part``, ``node_sets``, ``probes``, ``probe_roles``) and the file
    attributes."""
    import h5py

    with h5py.File(path, "r") as f:
        g = f["mesh"]
        names = [n.decode() if isinstance(n, bytes) else n for n in g["probes/names"][()]]
        coords = g["probes/coords"][()]
        roles = ([r.decode() if isinstance(r, bytes) else r for r in g["probes/roles"][()]]
                 if "probes/roles" in g else [])
        fields = dict(points=g["points"][()], hexes=g["hexes"][()], hex_part=g["hex_part"][()],
                      lines=g["lines"][()], line_part=g["line_part"][()],
                      node_sets={k: v[()] for k, v in g["node_sets"].items()},
                      probes={n: tuple(map(float, c)) for n, c in zip(names, coords)},
                      probe_roles={n: r for n, r in zip(names, roles) if r})
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    return fields, attrs


def mesh_xdmf(h5_name: str, mesh: Mesh) -> str:
    """XDMF text describing ``mesh.h5`` (relative path ``h5_name``).

    Two grids share the points: ``solids`` (Hexahedron) and ``beams_and_pads``
    (Polyline; left out when the mesh has no line elements), each with ``part_id``.
    """
    def arr(name: str, a: np.ndarray) -> H5Array:
        return H5Array(h5_name, f"/mesh/{name}", a.shape, a.dtype.str)

    return mesh_document(arr("points", mesh.points), [
        CellBlock("solids", "Hexahedron", arr("hexes", mesh.hexes),
                  arr("hex_part", mesh.hex_part)),
        CellBlock("beams_and_pads", "Polyline", arr("lines", mesh.lines),
                  arr("line_part", mesh.line_part))])


def write_mesh_files(out_dir: Path, mesh: Mesh, attrs: dict[str, str]) -> str:
    """Write ``mesh.h5`` then ``mesh.xdmf`` (XDMF last: it never points at a partial file);
    returns the content digest of ``mesh.h5``."""
    h5 = out_dir / MESH_H5
    sha = write_mesh_h5(h5, mesh, attrs)
    write_text(out_dir / MESH_XDMF, mesh_xdmf(h5.name, mesh))
    return sha
