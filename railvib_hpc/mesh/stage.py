"""The ``mesh`` stage: build (or read) the model, check it, write it, report quality."""

from __future__ import annotations

import json
import time
from pathlib import Path

from .. import __version__
from ..config import Case
from ..errors import MeshError
from ..io.atomic import write_text_atomic
from ..log import Reporter
from ..schema import PARTS
from .gmsh_model import generate, read_msh
from .layout import build_layout
from .mesh_io import read_mesh_h5, write_mesh_files
from .model import Mesh
from .search import nonconformal_faces

#: Case sections that determine the mesh (its reuse key).
MESH_INPUTS = ("geometry", "track", "building", "mesh", "domain")


def make_mesh(case: Case, msh_path: Path | None = None) -> tuple[Mesh, dict]:
    """Generate the model with gmsh (or read ``mesh.file``) and attach the probe points.

    Raises
    ------
    MeshError
        When the mesh has inverted elements or lacks required physical groups.
    """
    t0 = time.perf_counter()
    layout = build_layout(case)
    if case["mesh.file"]:
        mesh = read_msh(case.resolve(case["mesh.file"]))
        timings = {"read_msh": time.perf_counter() - t0}
        source = str(case.resolve(case["mesh.file"]))
    else:
        mesh, timings = generate(layout, msh_path)
        source = "generated"
    mesh.probes = dict(layout.probes)
    mesh.probe_roles = dict(layout.probe_roles)
    t0 = time.perf_counter()
    quality = mesh.quality()
    quality["duplicate_nodes"] = mesh.duplicate_nodes()
    quality["unused_nodes"] = mesh.unused_nodes()
    quality["nonconformal_faces"] = nonconformal_faces(mesh)
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
        "probe_roles": dict(mesh.probe_roles),
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


def run_mesh_stage(case: Case, out_dir: Path, reporter: Reporter) -> tuple[Mesh, dict]:
    """Build or reuse the mesh in ``out_dir`` (rank 0 only). Returns mesh and report."""
    out_dir.mkdir(parents=True, exist_ok=True)
    key = case.digest(*MESH_INPUTS)
    h5 = out_dir / "mesh.h5"
    report_path = out_dir / "mesh_report.json"
    if h5.exists() and report_path.exists():
        try:
            mesh, attrs = read_mesh_h5(h5)
            if attrs.get("inputs_sha256") == key:
                reporter.info(f"reusing {h5} (same mesh inputs)")
                if not mesh.probe_roles:      # mesh.h5 written before probes had roles
                    mesh.probe_roles = dict(build_layout(case).probe_roles)
                report = json.loads(report_path.read_text())
                report["reused"] = True
                return mesh, report
        except (OSError, KeyError, ValueError) as exc:
            reporter.info(f"ignoring unreadable {h5} ({exc}); rebuilding")
    mesh, report = make_mesh(case, out_dir / "mesh.msh" if not case["mesh.file"] else None)
    attrs = {"inputs_sha256": key, "railvib_version": __version__, "case_toml": case.to_toml()}
    t0 = time.perf_counter()
    write_mesh_files(out_dir, mesh, attrs)
    report["timings"]["write_h5_xdmf"] = time.perf_counter() - t0
    report["reused"] = False
    write_text_atomic(report_path, json.dumps(report, indent=2))
    return mesh, report
