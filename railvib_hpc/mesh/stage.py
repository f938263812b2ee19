"""The ``mesh`` stage: build (or read) the model, check it, write it, report quality."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..errors import MeshError
from ..io.atomic import write_text
from ..io.files import MESH_H5, MESH_MSH, MESH_REPORT_JSON, MESH_XDMF
from ..io.formats.mesh import check_mesh, write_mesh_files
from ..io.products import Selection, StageFile
from ..io.stage_outputs import MeshOutput
from ..io.stage_protocol import NotReusable, Stage, StageContext, StageInput, StageRunner
from ..log import Reporter
from ..parallel import on_root
from ..resources import check_memory, release_memory
from ..schema import PARTS
from .checks import (  # noqa: F401 (some re-exported: the checks live in mesh.checks)
    ASPECT_RATIO_WARNING,
    TINY_ELEMENT_FACTOR,
    max_edge_per_soil_part,
    present_parts,
    quality_warnings,
    require_parts,
    wavelength_warnings,
)
from .gmsh_model import generate, read_msh
from .interfaces import interface_nodes, split_interfaces
from .layout import Layout, build_layout
from .mesh_io import read_mesh_h5
from .model import Mesh
from .search import nonconformal_faces
from .turn import turn_building, turn_line, turn_map

if TYPE_CHECKING:
    from mpi4py import MPI

#: Memory per hexahedron of the mesh stage: its peak is gmsh's model while it meshes and the
#: mesh is extracted, 2.17 GB for 2,674,714 hexahedra (0.81 kB each; ``bench/mesh_bench.py
#: --site``, the 3 M-node site of docs/model.md), the batched checks and writes stay below
#: it; rounded up.
MESH_BYTES_PER_HEX = 1.0e3
#: Size of the binary ``mesh.msh`` per hexahedron: 3.57 MB for the 8,556 of refinement 0.5
#: (417 B, with the nodes, beams, pads and boundary quads), rounded up.
MSH_BYTES_PER_HEX = 450


def predicted_hexes(layout: Layout) -> int:
    """Number of hexahedra gmsh will make of a layout (exact: transfinite blocks)."""
    return int(sum(int(layout.nx[b.i]) * int(layout.ny[b.j])
                   * layout.zdiv[(round(b.z0, 9), round(b.z1, 9))] for b in layout.blocks))

def add_dispersion(report: dict, case: Case) -> None:
    """The numerical dispersion at the farthest probe into ``report`` (``dispersion``, its
    warnings; :func:`~.dispersion_check.dispersion_report`); nothing when
    ``mesh.wavelength_hz`` is 0.

    Raises
    ------
    DispersionError
        (a :class:`MeshError`) When the predicted error reaches ``mesh.max_dispersion_error``.
    """
    from .dispersion_check import dispersion_report

    report.pop("dispersion", None)
    found = dispersion_report(report["quality"], case, report.get("probes", {}))
    if found is not None:
        report["dispersion"] = found
        report["warnings"] = report["warnings"] + found["warnings"]


def make_mesh(case: Case, msh_path: Path | None = None) -> tuple[Mesh, dict]:
    """Generate the model with gmsh (or read ``mesh.file``) and attach the probe points.

    Raises
    ------
    MeshError
        When the mesh has inverted elements or lacks required physical groups.
    """
    t0 = time.perf_counter()
    layout = build_layout(case)
    derived, dropped = [], {}
    n_hex = 0
    if not case["mesh.file"]:
        n_hex = predicted_hexes(layout)
        check_memory(n_hex * MESH_BYTES_PER_HEX, f"the mesh ({n_hex:.3g} hexahedra at "
                     f"mesh.refinement = {case['mesh.refinement']:g})",
                     "check mesh.refinement and the [mesh] element counts and sizes")
    twist_map = None
    if case["mesh.file"]:
        mesh = read_msh(case.resolve(case["mesh.file"]))
        timings = {"read_msh": time.perf_counter() - t0}
        source = str(case.resolve(case["mesh.file"]))
        derived = complete_node_sets(mesh)
        mesh.probes, dropped = probes_inside(mesh, layout.probes)
    else:
        twist_map = turn_map(case, layout)
        mesh, timings = generate(layout, msh_path, msh_size=MSH_BYTES_PER_HEX * n_hex,
                                 msh_map=twist_map)
        mesh.probes = dict(layout.probes)
        mesh = split_interfaces(mesh, case)          # under-sleeper pads, mats, isolation
        mesh = turn_building(mesh, case, layout, twist_map)  # building.rotation
        source = "generated"
    mesh.probe_roles = {k: r for k, r in layout.probe_roles.items() if k in mesh.probes}
    release_memory()                    # gmsh's freed model (GBs at millions of elements)
    quality = check_quality(mesh, timings)
    if quality["n_inverted"]:
        raise MeshError(f"mesh has {quality['n_inverted']} inverted hexahedra (non-positive "
                        f"scaled Jacobian, min {quality['min_scaled_jacobian']:.3g}); fix the "
                        "geometry or the mesh file")
    t0 = time.perf_counter()
    report = {
        "source": source,
        "quality": quality,
        "warnings": (quality_warnings(quality, case["modal.tol"])
                     + wavelength_warnings(quality, case)),
        "elements_per_part": mesh.counts_per_part(),
        "nodes_per_part": mesh.nodes_per_part(),
        "volume_per_part": mesh.volume_per_part(),
        "node_sets": {k: len(v) for k, v in mesh.node_sets.items()},
        "probes": {k: list(v) for k, v in mesh.probes.items()},
        "probe_roles": dict(mesh.probe_roles),
        "parts": present_parts(mesh),
        "node_sets_derived": derived,
        "probes_outside": {k: list(v) for k, v in dropped.items()},
        "turn": turn_line(case) + ("; the ring's soil relaxed to keep corner angles within "
                                   "25-155 deg" if twist_map is not None and twist_map.relaxed
                                   else ""),
        "timings": timings,
    }
    timings["report"] = time.perf_counter() - t0
    add_dispersion(report, case)            # may refuse: before any file but mesh.msh
    return mesh, report


def check_quality(mesh: Mesh, timings: dict[str, float]) -> dict:
    """The mesh check's numbers (:meth:`~.model.Mesh.quality`, duplicate and unused nodes,
    non-conformal faces, the longest edge per soil part); adds the seconds of its parts to
    ``timings`` (``check_elements``, ``check_nodes``, ``check_faces``) and their sum
    (``quality``)."""
    t0 = time.perf_counter()
    measures = mesh.element_measures()                  # one pass over the elements
    quality = mesh.quality(measures)
    longest = max_edge_per_soil_part(mesh, measures[2])
    del measures
    t1 = time.perf_counter()
    # the elastic interfaces' node pairs coincide and their faces are not shared, by design
    joined = interface_nodes(mesh)
    quality["duplicate_nodes"] = mesh.duplicate_nodes() - joined.size // 2
    quality["unused_nodes"] = mesh.unused_nodes()
    t2 = time.perf_counter()
    quality["nonconformal_faces"] = nonconformal_faces(mesh, exclude_nodes=joined)
    quality["max_edge_per_soil_part"] = longest
    t3 = time.perf_counter()
    timings.update(check_elements=t1 - t0, check_nodes=t2 - t1, check_faces=t3 - t2,
                   quality=t3 - t0)
    return quality


def complete_node_sets(mesh: Mesh, rel_tol: float = 1e-9) -> list[str]:
    """Add the boundary node sets a user mesh does not define, as the generator defines
    them: ``bottom`` = hexahedron nodes at the lowest z, ``x_faces`` / ``y_faces`` = those
    at the smallest or largest x / y (Appendix A: bottom fixed, rollers on the sides).
    Returns the names added."""
    added = []
    used = np.unique(mesh.hexes)
    if used.size == 0:
        return added
    p = mesh.points[used]
    lo, hi = p.min(axis=0), p.max(axis=0)
    tol = rel_tol * max(float(np.max(hi - lo)), 1.0)
    rules = {"bottom": np.abs(p[:, 2] - lo[2]) <= tol,
             "x_faces": (np.abs(p[:, 0] - lo[0]) <= tol) | (np.abs(p[:, 0] - hi[0]) <= tol),
             "y_faces": (np.abs(p[:, 1] - lo[1]) <= tol) | (np.abs(p[:, 1] - hi[1]) <= tol)}
    for name, mask in rules.items():
        if name not in mesh.node_sets:
            mesh.node_sets[name] = used[mask]
            added.append(name)
    return added


def probes_inside(mesh: Mesh, probes: dict) -> tuple[dict, dict]:
    """Split the named probe points into those inside the hexahedra and those outside
    (a partial user mesh: a soil column has no slab)."""
    from .search import locate

    if not probes or len(mesh.hexes) == 0:
        return {}, dict(probes)
    names = list(probes)
    elem, _ = locate(np.array([probes[k] for k in names], dtype=float), mesh)
    inside = {k: probes[k] for k, e in zip(names, elem) if e >= 0}
    return inside, {k: probes[k] for k, e in zip(names, elem) if e < 0}


def format_report(report: dict) -> str:
    """Human-readable quality report."""
    q = report["quality"]
    # the parts the model has (mesh_report.json lists every part, the empty ones with 0)
    parts = [p for p in PARTS if report["elements_per_part"].get(p, 0) > 0]
    width = max([12, *map(len, parts)])
    lines = [f"{'part':<{width}} {'elements':>9} {'nodes':>9} {'volume [m3]':>12}"]
    for p in parts:
        vol = report["volume_per_part"].get(p)
        lines.append(f"{p:<{width}} {report['elements_per_part'][p]:>9d} "
                     f"{report['nodes_per_part'][p]:>9d} "
                     f"{'' if vol is None else f'{vol:12.4f}':>12}")
    lines += [
        f"nodes {q['n_nodes']}, hexahedra {q['n_hexes']}, beam/spring elements {q['n_lines']}",
        f"min scaled Jacobian {q['min_scaled_jacobian']:.4f}, max aspect ratio "
        f"{q['max_aspect_ratio']:.3f}, inverted {q['n_inverted']}",
        f"duplicate nodes {q['duplicate_nodes']}, unused nodes {q['unused_nodes']}, "
        f"non-conformal faces {q['nonconformal_faces']}",
        "node sets: " + ", ".join(f"{k} {v}" for k, v in report["node_sets"].items()),
    ]
    if report.get("turn"):
        lines.append(report["turn"])
    if report.get("dispersion"):
        lines.append(report["dispersion"]["line"])
    lines += user_mesh_notes(report)
    return "\n".join(lines)


def user_mesh_notes(report: dict) -> list[str]:
    """What was completed or left out of a user mesh (``mesh.file``), one line each."""
    out = []
    if report.get("node_sets_derived"):
        out.append("node sets derived from the bounding box (not in mesh.file): "
                   + ", ".join(report["node_sets_derived"]))
    if report.get("probes_outside"):
        out.append("probe points outside the mesh (left out): "
                   + ", ".join(report["probes_outside"]))
    return out


def build_or_reuse_mesh(ctx: StageContext) -> tuple[Mesh, dict, str]:
    """Reuse ``mesh.h5`` of the context's folder when it is current and sound, else build
    and write it (rank 0 only).

    Returns
    -------
    tuple
        The mesh, its quality report (``reused`` set) and the content digest of
        ``mesh.h5``.
    """
    case, out_dir, reporter = ctx.case, ctx.out_dir, ctx.rep
    out_dir.mkdir(parents=True, exist_ok=True)
    h5 = out_dir / MESH_H5
    report_path = out_dir / MESH_REPORT_JSON
    msh = None if case["mesh.file"] else out_dir / MESH_MSH

    def read(verdict) -> tuple[Mesh, dict]:
        if msh is not None and not msh.exists():
            raise NotReusable("it lacks mesh.msh, written with it")
        try:
            mesh, _ = read_mesh_h5(h5)
            if not mesh.probe_roles:      # mesh.h5 written before probes had roles
                mesh.probe_roles = dict(build_layout(case).probe_roles)
            return mesh, json.loads(report_path.read_text())
        except (OSError, KeyError, ValueError) as exc:
            raise NotReusable(f"it cannot be read ({exc})") from None

    old = ctx.reuse(MESH_H5, path=h5, why="same mesh inputs", accept=read)
    if old.ok:
        mesh, report = old.value
        report["reused"] = True
        report["warnings"] = (quality_warnings(report["quality"], case["modal.tol"])
                              + wavelength_warnings(report["quality"], case))
        add_dispersion(report, case)        # output.probes and the limit are not mesh inputs
        _print_warnings(report, reporter)
        return mesh, report, old.sha256
    try:
        mesh, report = make_mesh(case, msh)
    except MeshError:
        if msh is not None:                 # mesh.msh is only ever left with its mesh.h5
            msh.unlink(missing_ok=True)
        raise
    t0 = time.perf_counter()
    sha = write_mesh_files(out_dir, mesh, ctx.provenance(MESH_H5, {}))
    report["timings"]["write_h5_xdmf"] = time.perf_counter() - t0
    report["reused"] = False
    write_text(report_path, json.dumps(report, indent=2))
    _print_warnings(report, reporter)
    return mesh, report, sha


def provide(ctx: StageContext) -> StageInput:
    """The mesh for a stage that needs it (``ctx.input("mesh")``; rank 0): ``mesh.h5`` of
    the context's folder built or reused (:func:`build_or_reuse_mesh`), loaded, with its
    digest and quality report."""
    mesh, report, sha = build_or_reuse_mesh(ctx)
    return StageInput("mesh", {MESH_H5: sha}, {MESH_H5: ctx.path(MESH_H5)}, value=mesh,
                      detail=report)


def compute(ctx: StageContext) -> MeshOutput:
    """``railvib mesh``: build or reuse ``mesh.h5`` and print the quality report (collective;
    gmsh runs on rank 0)."""
    case, out_dir, rep = ctx.case, ctx.out_dir, ctx.rep

    def work() -> MeshOutput:
        with rep.stage("mesh"):
            _, report, _ = build_or_reuse_mesh(ctx)
        rep.info(format_report(report))
        rep.info("mesh timings: " + ", ".join(f"{k} {v:.2f} s"
                                                for k, v in report["timings"].items()))
        rep.info(f"wrote {out_dir / MESH_XDMF} (open in ParaView), {out_dir / MESH_H5}"
                 + ("" if case["mesh.file"] else f", {out_dir / MESH_MSH}"))
        return MeshOutput.of_report(report, out_dir, bool(case["mesh.file"]))

    return on_root(work, ctx.comm)


#: The soils' damping ratios do not size the mesh (their E, nu, rho do).
_SOIL_WAVE_SPEED = ("damping_ratio",)
#: The case keys of the mesh: its geometry and divisions, the soil layers, the elastic
#: interfaces (they cut the mesh), and the soils' E, nu, rho (the wavelength sizing,
#: mesh.elements_per_wavelength, reads their shear-wave speeds). (The supported track
#: ends' springs and dashpots are K's and C's, not the mesh's.) Every later product
#: depends on them.
MESH_KEYS: Selection = (
    ("geometry", ()), ("track", ("end_stiffness", "end_damping")), ("building", ()),
    ("mesh", ()), ("domain", ()), ("soil", ()), ("trench", ()), ("wib", ()), ("usp", ()),
    ("ballast_mat", ()), ("isolation", ()), ("materials.ballast", _SOIL_WAVE_SPEED),
    ("materials.subballast", _SOIL_WAVE_SPEED), ("materials.subgrade", _SOIL_WAVE_SPEED))
#: ``mesh.h5`` (with its XDMF view and quality report; the content of ``mesh.file``).
MESH_FILE = StageFile(MESH_H5, "mesh", 2, MESH_KEYS, (), (MESH_XDMF, MESH_REPORT_JSON),
                      ("mesh.file",), check=check_mesh)

STAGE = Stage(name="mesh", help="build the gmsh model, check its quality, write "
              "mesh.msh/.h5/.xdmf", products=(MESH_FILE,), compute=compute, provide=provide)


def run_mesh_stage(case: Case, out_dir: Path, comm: MPI.Comm, rep: Reporter,
                   petsc_options: list[str] | None = None) -> dict:
    """The ``mesh`` stage from a script: :data:`STAGE` through the runner (the folder's
    lock; no ``run.json`` entry). Returns the quality report (every rank)."""
    runner = StageRunner(out_dir, comm, rep, petsc_options or (), command="mesh")
    return dict(runner.run(STAGE, case, record=False).result.summary)


def _print_warnings(report: dict, reporter: Reporter) -> None:
    """The mesh check's warnings, and what was completed or left out of a user mesh."""
    for warning in report.get("warnings", []):
        reporter.info(f"WARNING (mesh check): {warning}")
    for note in user_mesh_notes(report):
        reporter.info(f"note: {note}")
