"""The ``mesh`` stage: build (or read) the model, check it, write it, report quality."""

from __future__ import annotations

import json
import time
from pathlib import Path

from ..config import Case
from ..errors import MeshError
from ..io.mesh_io import read_mesh_h5, write_mesh_files
from ..io.stage_checks import check_mesh
from ..io.stage_files import examine, forget, output_lock, provenance, write_text
from ..log import Reporter
from ..parallel import on_root
from ..resources import check_memory
from ..schema import PARTS
from .gmsh_model import generate, read_msh
from .layout import Layout, build_layout
from .model import Mesh

#: Case sections that determine the mesh (see ``mesh.h5`` in
#: :data:`railvib_hpc.io.stage_files.STAGE_FILES`).
MESH_INPUTS = ("geometry", "track", "building", "mesh", "domain")
#: Memory per hexahedron while gmsh meshes and the mesh is extracted: 0.7 kB measured on the
#: thesis model (52,056 hexahedra: +29 MB over 8,556), times 3 for the quality checks.
MESH_BYTES_PER_HEX = 2.0e3
#: Size of the binary ``mesh.msh`` per hexahedron: 3.57 MB for the 8,556 of refinement 0.5
#: (417 B, with the nodes, beams, pads and boundary quads), rounded up.
MSH_BYTES_PER_HEX = 450


def predicted_hexes(layout: Layout) -> int:
    """Number of hexahedra gmsh will make of a layout (exact: transfinite blocks)."""
    return int(sum(int(layout.nx[b.i]) * int(layout.ny[b.j])
                   * layout.zdiv[(round(b.z0, 9), round(b.z1, 9))] for b in layout.blocks))


def make_mesh(case: Case, msh_path: Path | None = None) -> tuple[Mesh, dict]:
    """Generate the model with gmsh (or read ``mesh.file``) and attach the probe points.

    Raises
    ------
    MeshError
        When the mesh has inverted elements or lacks required physical groups.
    """
    t0 = time.perf_counter()
    layout = build_layout(case)
    n_hex = 0
    if not case["mesh.file"]:
        n_hex = predicted_hexes(layout)
        check_memory(n_hex * MESH_BYTES_PER_HEX, f"the mesh ({n_hex:.3g} hexahedra at "
                     f"mesh.refinement = {case['mesh.refinement']:g})",
                     "check mesh.refinement and the [mesh] element counts and sizes")
    if case["mesh.file"]:
        mesh = read_msh(case.resolve(case["mesh.file"]))
        timings = {"read_msh": time.perf_counter() - t0}
        source = str(case.resolve(case["mesh.file"]))
    else:
        mesh, timings = generate(layout, msh_path, msh_size=MSH_BYTES_PER_HEX * n_hex)
        source = "generated"
    mesh.probes = dict(layout.probes)
    t0 = time.perf_counter()
    quality = mesh.quality()
    quality["duplicate_nodes"] = mesh.duplicate_nodes()
    quality["unused_nodes"] = mesh.unused_nodes()
    quality["nonconformal_faces"] = mesh.nonconformal_faces()
    timings["quality"] = time.perf_counter() - t0
    if quality["n_inverted"]:
        raise MeshError(f"mesh has {quality['n_inverted']} inverted hexahedra (non-positive "
                        f"scaled Jacobian, min {quality['min_scaled_jacobian']:.3g}); fix the "
                        "geometry or the mesh file")
    report = {
        "source": source,
        "quality": quality,
        "elements_per_part": mesh.counts_per_part(),
        "nodes_per_part": mesh.nodes_per_part(),
        "volume_per_part": mesh.volume_per_part(),
        "node_sets": {k: len(v) for k, v in mesh.node_sets.items()},
        "probes": {k: list(v) for k, v in mesh.probes.items()},
        "timings": timings,
    }
    return mesh, report


def format_report(report: dict) -> str:
    """Human-readable quality report."""
    q = report["quality"]
    lines = [f"{'part':<12} {'elements':>9} {'nodes':>9} {'volume [m3]':>12}"]
    for p in PARTS:
        vol = report["volume_per_part"].get(p)
        lines.append(f"{p:<12} {report['elements_per_part'][p]:>9d} "
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
    return "\n".join(lines)


def build_or_reuse_mesh(case: Case, out_dir: Path, reporter: Reporter
                        ) -> tuple[Mesh, dict, str]:
    """Reuse ``mesh.h5`` of ``out_dir`` when it is current and sound, else build and write
    it (rank 0 only).

    Returns
    -------
    tuple
        The mesh, its quality report (``reused`` set) and the content digest of
        ``mesh.h5``.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    h5 = out_dir / "mesh.h5"
    report_path = out_dir / "mesh_report.json"
    msh = None if case["mesh.file"] else out_dir / "mesh.msh"
    verdict = examine(h5, "mesh.h5", case, data_check=check_mesh)
    if verdict.ok and msh is not None and not msh.exists():
        verdict.ok, verdict.reason = False, "it lacks mesh.msh, written with it"
    if verdict.ok:
        try:
            mesh, _ = read_mesh_h5(h5)
            report = json.loads(report_path.read_text())
            reporter.info(f"reusing {h5} (same mesh inputs)")
            report["reused"] = True
            return mesh, report, verdict.sha256
        except (OSError, KeyError, ValueError) as exc:
            verdict.reason = f"it cannot be read ({exc})"
    if verdict.kind != "missing":
        reporter.info(f"recomputing {h5}: {verdict.reason}")
    forget(h5)
    mesh, report = make_mesh(case, msh)
    t0 = time.perf_counter()
    sha = write_mesh_files(out_dir, mesh, provenance("mesh.h5", case, {}))
    report["timings"]["write_h5_xdmf"] = time.perf_counter() - t0
    report["reused"] = False
    write_text(report_path, json.dumps(report, indent=2))
    return mesh, report, sha


def run_mesh_stage(case: Case, out_dir: Path, comm, rep: Reporter,
                   petsc_options: list[str] | None = None) -> dict:
    """``railvib mesh``: build or reuse ``mesh.h5`` and print the quality report (collective;
    gmsh runs on rank 0). Returns the report (every rank)."""
    out_dir = Path(out_dir)

    def work() -> dict:
        with rep.stage("mesh"):
            _, report, _ = build_or_reuse_mesh(case, out_dir, rep)
        rep.info(format_report(report))
        rep.info("mesh timings: " + ", ".join(f"{k} {v:.2f} s"
                                                for k, v in report["timings"].items()))
        rep.info(f"wrote {out_dir / 'mesh.xdmf'} (open in ParaView), {out_dir / 'mesh.h5'}"
                 + ("" if case["mesh.file"] else f", {out_dir / 'mesh.msh'}"))
        return report

    with output_lock(out_dir, comm, "mesh", rep=rep):
        return on_root(work, comm)
