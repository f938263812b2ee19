"""``mesh.h5``: its layout and check (the mesh stage's model in HDF5).

Layout (HDF5)::

    /mesh/points (n, 3), /mesh/hexes (ne, 8) (VTK/gmsh node order), /mesh/hex_part (ne,),
    /mesh/lines (nl, 2), /mesh/line_part (nl,), /mesh/node_sets/{bottom,x_faces,y_faces},
    /mesh/probes/{names,coords,nearest_node}
    attrs: part_names (JSON id -> name) and the provenance

Writer and reader: :func:`railvib_hpc.mesh.mesh_io.write_mesh_h5` and
:func:`~railvib_hpc.mesh.mesh_io.read_mesh_h5` (they build the mesh model of
:mod:`railvib_hpc.mesh.model`, a layer above this one). Check: :func:`check_mesh` (on
write and on reuse), :func:`check_mesh_arrays` (the arrays in memory).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .checks import absent, h5_read, nonfinite


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
