"""Mesh files: ``mesh.h5`` (arrays + provenance) and ``mesh.xdmf`` for ParaView.

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
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io.atomic import write_h5, write_text
from ..io.files import MESH_H5, MESH_XDMF
from ..io.xdmf import CellBlock, H5Array, mesh_document
from ..schema import PART_ID
from .model import Mesh


def mesh_nbytes(mesh: Mesh) -> int:
    """Predicted size of ``mesh.h5`` [bytes] (its arrays)."""
    sets = sum(np.asarray(v).nbytes for v in mesh.node_sets.values())
    return int(mesh.points.nbytes + mesh.hexes.nbytes + mesh.hex_part.nbytes + mesh.lines.nbytes
               + mesh.line_part.nbytes + sets + 128 * len(mesh.probes))


def write_mesh_h5(path: Path, mesh: Mesh, attrs: dict[str, str]) -> str:
    """Write ``mesh.h5`` atomically, checked and recorded (serial, rank 0); returns its
    content digest."""
    import h5py

    from ..io.formats.mesh import check_mesh

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


def read_mesh_h5(path: Path) -> tuple[Mesh, dict]:
    """Read ``mesh.h5``; returns the mesh and the file attributes."""
    import h5py

    with h5py.File(path, "r") as f:
        g = f["mesh"]
        names = [n.decode() if isinstance(n, bytes) else n for n in g["probes/names"][()]]
        coords = g["probes/coords"][()]
        roles = ([r.decode() if isinstance(r, bytes) else r for r in g["probes/roles"][()]]
                 if "probes/roles" in g else [])
        mesh = Mesh(points=g["points"][()], hexes=g["hexes"][()], hex_part=g["hex_part"][()],
                    lines=g["lines"][()], line_part=g["line_part"][()],
                    node_sets={k: v[()] for k, v in g["node_sets"].items()},
                    probes={n: tuple(map(float, c)) for n, c in zip(names, coords)},
                    probe_roles={n: r for n, r in zip(names, roles) if r})
        attrs = {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}
    return mesh, attrs


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
