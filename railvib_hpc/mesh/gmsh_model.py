"""Build the thesis model with gmsh (rank 0 only) and read gmsh meshes.

The geometry is created with gmsh's built-in kernel as structured blocks from
:mod:`railvib_hpc.mesh.layout`; every block is a transfinite, recombined volume
(8-node hexahedra). Rails are transfinite curves at the rail height, sleepers
are the block edges on the ballast crest (so they share the ballast surface
nodes), rail pads are one-element curves from each rail node above a sleeper to
the sleeper node below, in three physical groups ``pad_x``, ``pad_y``,
``pad_z`` over the same curves (three spring elements per crossing).
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from ..errors import MeshError
from ..schema import BEAM_PARTS, PAD_PARTS, PART_ID, SOLID_PARTS
from .layout import Layout
from .model import Mesh, node_order

NODE_SETS = ("bottom", "x_faces", "y_faces")


@contextmanager
def gmsh_session(verbose: bool = False):
    """Initialise gmsh for the duration of a ``with`` block (rank 0 only)."""
    import gmsh

    gmsh.initialize(["-noenv"], readConfigFiles=False)
    gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
    gmsh.option.setNumber("General.NumThreads", 1)
    try:
        yield gmsh
    finally:
        gmsh.finalize()


def build_geometry(gmsh, lay: Layout) -> None:
    """Create points, curves, surfaces and volumes of the layout, with transfinite settings."""
    geo = gmsh.model.geo
    points: dict[tuple, int] = {}
    lines: dict[tuple, int] = {}
    surfaces: dict[frozenset, int] = {}
    by_part: dict[str, list[int]] = {p: [] for p in SOLID_PARTS}
    boundary: dict[str, list[int]] = {s: [] for s in NODE_SETS}
    xmin, xmax, ymin, ymax, zmin, _ = lay.bounds
    eps = 1e-7

    def point(key: tuple) -> int:
        tag = points.get(key)
        if tag is None:
            tag = geo.addPoint(*lay.vertex(*key))
            points[key] = tag
        return tag

    def line(ka: tuple, kb: tuple, ndiv: int) -> int:
        """Signed tag of the curve from vertex ka to kb."""
        key = (ka, kb) if ka < kb else (kb, ka)
        tag = lines.get(key)
        if tag is None:
            tag = geo.addLine(point(key[0]), point(key[1]))
            geo.mesh.setTransfiniteCurve(tag, ndiv + 1)
            lines[key] = tag
        return tag if key[0] == ka else -tag

    def face(corners: list[tuple], divs: list[int]) -> int:
        key = frozenset(corners)
        tag = surfaces.get(key)
        if tag is None:
            loop = [line(corners[k], corners[(k + 1) % 4], divs[k]) for k in range(4)]
            tag = geo.addPlaneSurface([geo.addCurveLoop(loop)])
            geo.mesh.setTransfiniteSurface(tag)
            geo.mesh.setRecombine(2, tag)
            surfaces[key] = tag
        return tag

    for blk in lay.blocks:
        i, j, z0, z1 = blk.i, blk.j, round(blk.z0, 9), round(blk.z1, 9)
        nx, ny, nz = int(lay.nx[i]), int(lay.ny[j]), lay.zdiv[(z0, z1)]
        v = {(a, b, c): (i + a, j + b, (z0, z1)[c]) for a in (0, 1) for b in (0, 1) for c in (0, 1)}
        faces = {
            "zlo": face([v[0, 0, 0], v[1, 0, 0], v[1, 1, 0], v[0, 1, 0]], [nx, ny, nx, ny]),
            "zhi": face([v[0, 0, 1], v[1, 0, 1], v[1, 1, 1], v[0, 1, 1]], [nx, ny, nx, ny]),
            "ylo": face([v[0, 0, 0], v[1, 0, 0], v[1, 0, 1], v[0, 0, 1]], [nx, nz, nx, nz]),
            "yhi": face([v[0, 1, 0], v[1, 1, 0], v[1, 1, 1], v[0, 1, 1]], [nx, nz, nx, nz]),
            "xlo": face([v[0, 0, 0], v[0, 1, 0], v[0, 1, 1], v[0, 0, 1]], [ny, nz, ny, nz]),
            "xhi": face([v[1, 0, 0], v[1, 1, 0], v[1, 1, 1], v[1, 0, 1]], [ny, nz, ny, nz]),
        }
        vol = geo.addVolume([geo.addSurfaceLoop(list(faces.values()))])
        geo.mesh.setTransfiniteVolume(vol)
        by_part[blk.part].append(vol)
        x_lo, x_hi = lay.xb[i], lay.xb[i + 1]
        y_lo, y_hi = lay.yb[j], lay.yb[j + 1]
        if abs(blk.z0 - zmin) < eps:
            boundary["bottom"].append(faces["zlo"])
        if abs(x_lo - xmin) < eps:
            boundary["x_faces"].append(faces["xlo"])
        if abs(x_hi - xmax) < eps:
            boundary["x_faces"].append(faces["xhi"])
        if abs(y_lo - ymin) < eps:
            boundary["y_faces"].append(faces["ylo"])
        if abs(y_hi - ymax) < eps:
            boundary["y_faces"].append(faces["yhi"])

    # --- rails, sleepers, pads
    ix = {round(float(x), 9): k for k, x in enumerate(lay.xb)}
    iy = {round(float(y), 9): k for k, y in enumerate(lay.yb)}
    zs = round(lay.sleeper_z, 9)
    sleeper_curves, rail_curves, rigid_curves, pad_curves = [], [], [], []
    for y in lay.rail_y:
        rail_pts = [geo.addPoint(lay.rigid_ends[0], y, lay.rail_z)]
        rail_pts += [geo.addPoint(float(x), y, lay.rail_z) for x in lay.sleeper_x]
        rail_pts.append(geo.addPoint(lay.rigid_ends[1], y, lay.rail_z))
        for k in range(len(rail_pts) - 1):
            c = geo.addLine(rail_pts[k], rail_pts[k + 1])
            end = k == 0 or k == len(rail_pts) - 2
            # the end sections: one rigid element, or the supported rail (track.ends)
            geo.mesh.setTransfiniteCurve(c, (lay.end_div or 1) + 1 if end
                                         else lay.rail_div + 1)
            (rigid_curves if end and not lay.end_div else rail_curves).append(c)
        jy = iy[round(y, 9)]
        for k, x in enumerate(lay.sleeper_x):
            c = geo.addLine(rail_pts[k + 1], point((ix[round(float(x), 9)], jy, zs)))
            geo.mesh.setTransfiniteCurve(c, 2)
            pad_curves.append(c)
    for track_y in np.atleast_2d(lay.sleeper_y):
        js = [iy[round(float(y), 9)] for y in track_y]
        for x in lay.sleeper_x:
            i = ix[round(float(x), 9)]
            for j in range(js[0], js[-1]):
                sleeper_curves.append(abs(lines[((i, j, zs), (i, j + 1, zs))]))

    geo.synchronize()
    for part, vols in by_part.items():
        if vols:
            gmsh.model.addPhysicalGroup(3, vols, PART_ID[part], name=part)
    for part, curves in (("rail", rail_curves), ("rigid_rail", rigid_curves),
                         ("sleeper", sleeper_curves)):
        if curves:                    # (no rigid rail with track.ends = 'supported')
            gmsh.model.addPhysicalGroup(1, curves, PART_ID[part], name=part)
    for part in PAD_PARTS if pad_curves else ():      # (none on the bare soil)
        gmsh.model.addPhysicalGroup(1, pad_curves, PART_ID[part], name=part)
    for k, (name, faces) in enumerate(boundary.items()):
        gmsh.model.addPhysicalGroup(2, sorted(set(faces)), 101 + k, name=name)


def extract_mesh(gmsh) -> Mesh:
    """Read nodes, hexahedra, beam/pad elements and node sets from the current gmsh model.

    Raises
    ------
    MeshError
        Missing physical groups or unsupported element types.
    """
    tags, coords, _ = gmsh.model.mesh.getNodes()
    tags = np.asarray(tags, dtype=np.int64)
    coords = np.asarray(coords).reshape(-1, 3)
    # Renumber nodes lexicographically by (x, y, z): contiguous node ranges are then compact
    # slabs along the track, which is how the parallel stages split ownership across ranks.
    order = node_order(coords)
    tags, coords = tags[order], coords[order]
    index = np.full(tags.max() + 1, -1, dtype=np.int64)
    index[tags] = np.arange(len(tags))

    groups = {gmsh.model.getPhysicalName(d, t): (d, t) for d, t in gmsh.model.getPhysicalGroups()}
    # any subset of the parts is a model (a soil column, a track without building, ...);
    # the stages that need rails, sleepers or pads say so themselves
    known = (*SOLID_PARTS, *BEAM_PARTS, *PAD_PARTS)
    if not any(p in groups for p in known):
        found = ", ".join(repr(g) for g in groups) or "none"
        raise MeshError(f"mesh has no physical group named after a part (found: {found}); "
                        f"allowed names: {', '.join(known)} (node sets: "
                        f"{', '.join(NODE_SETS)})")

    def elements(dim: int, tag: int, etype: int, nper: int) -> np.ndarray:
        chunks = []
        for ent in gmsh.model.getEntitiesForPhysicalGroup(dim, tag):
            types = gmsh.model.mesh.getElementTypes(dim, ent)
            bad = [t for t in types if t != etype]
            if bad:
                name = gmsh.model.mesh.getElementProperties(bad[0])[0]
                raise MeshError(f"physical group '{gmsh.model.getPhysicalName(dim, tag)}' holds "
                                f"'{name}' elements; only 8-node hexahedra (solids) and 2-node "
                                "lines (beams, pads) are supported")
            _, nodes = gmsh.model.mesh.getElementsByType(etype, ent)
            chunks.append(np.asarray(nodes, dtype=np.int64).reshape(-1, nper))
        if not chunks:
            return np.zeros((0, nper), dtype=np.int64)
        return index[np.concatenate(chunks)]

    hexes, hex_part, lines, line_part = [], [], [], []
    for part in SOLID_PARTS:
        if part in groups:
            conn = elements(*groups[part], 5, 8)
            hexes.append(conn)
            hex_part.append(np.full(len(conn), PART_ID[part], dtype=np.int32))
    for part in (*BEAM_PARTS, *PAD_PARTS):
        if part in groups:
            conn = elements(*groups[part], 1, 2)
            lines.append(conn)
            line_part.append(np.full(len(conn), PART_ID[part], dtype=np.int32))
    node_sets = {}
    for name in NODE_SETS:
        if name in groups:
            nodes, _ = gmsh.model.mesh.getNodesForPhysicalGroup(*groups[name])
            node_sets[name] = np.unique(index[np.asarray(nodes, dtype=np.int64)])
    def stack(arrays, width, dtype):
        return np.concatenate(arrays) if arrays else np.zeros((0, width) if width else 0, dtype)

    return Mesh(points=coords, hexes=stack(hexes, 8, np.int64),
                hex_part=stack(hex_part, 0, np.int32), lines=stack(lines, 2, np.int64),
                line_part=stack(line_part, 0, np.int32), node_sets=node_sets)


def generate(lay: Layout, msh_path: Path | None = None, verbose: bool = False,
             msh_size: int = 0, msh_map=None) -> tuple[Mesh, dict]:
    """Generate the model with gmsh; optionally write the ``.msh``. Returns mesh and timings.

    ``msh_map`` (points (n, 3) -> points) moves the nodes of the written ``.msh`` only (a
    turned building, :mod:`.turn`, which the caller applies to the returned mesh too).

    The ``.msh`` is written under a temporary name and renamed only after it was read
    back (``gmsh.write`` reports no errors: a full disk leaves a truncated file); with
    ``msh_size`` (its predicted size) free space is checked first.

    Raises
    ------
    MeshError
        When gmsh fails on the geometry (it raises a bare ``Exception``).
    OutputError
        When the ``.msh`` cannot be written.
    """
    from contextlib import nullcontext

    from ..io.atomic import atomic_file

    timings = {}
    target = (atomic_file(msh_path, suffix=True, check=check_msh, size_hint=msh_size)
              if msh_path is not None else nullcontext(None))
    with target as tmp, gmsh_session(verbose) as gmsh:
        gmsh.model.add("railvib")
        t0 = time.perf_counter()
        try:
            build_geometry(gmsh, lay)
            timings["geometry"] = time.perf_counter() - t0
            t0 = time.perf_counter()
            gmsh.model.mesh.generate(3)
        except MeshError:
            raise
        except Exception as exc:  # gmsh raises a bare Exception
            raise MeshError(f"gmsh could not mesh the model ({exc}); check the [mesh] "
                            "element counts and sizes and the geometry") from None
        timings["meshing"] = time.perf_counter() - t0
        t0 = time.perf_counter()
        mesh = extract_mesh(gmsh)
        timings["extract"] = time.perf_counter() - t0
        if tmp is not None:
            t0 = time.perf_counter()
            if msh_map is not None:
                tags, xyz, _ = gmsh.model.mesh.getNodes()
                moved = msh_map(np.asarray(xyz, dtype=float).reshape(-1, 3))
                for tag, p in zip(tags.tolist(), moved.tolist()):
                    gmsh.model.mesh.setNode(tag, p, [])
            gmsh.option.setNumber("Mesh.Binary", 1)
            gmsh.write(str(tmp))
            timings["write_msh"] = time.perf_counter() - t0
        t0 = time.perf_counter()
    # gmsh's model freed, and the .msh read back (check_msh), synced and renamed
    timings["close_msh"] = time.perf_counter() - t0
    return mesh, timings


def check_msh(path: Path) -> list[str]:
    """Problems of a written ``.msh`` (empty list: gmsh reads it back with nodes)."""
    with gmsh_session() as gmsh:
        try:
            gmsh.open(str(path))
            tags, _, _ = gmsh.model.mesh.getNodes()
        except Exception as exc:  # gmsh raises a bare Exception
            return [f"gmsh cannot read it back ({exc})"]
    return [] if len(tags) else ["gmsh reads no nodes from it"]


def read_msh(path: Path) -> Mesh:
    """Read a user's gmsh ``.msh`` with the project's physical-group names."""
    with gmsh_session() as gmsh:
        try:
            gmsh.open(str(path))
        except Exception as exc:  # gmsh raises a bare Exception
            raise MeshError(f"mesh.file = '{path}': gmsh cannot read it ({exc})") from None
        if not len(gmsh.model.mesh.getNodes()[0]):
            raise MeshError(f"mesh.file = '{path}': it holds no nodes (an empty file or not a "
                            "gmsh mesh)")
        return extract_mesh(gmsh)
