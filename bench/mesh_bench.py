"""Mesh benchmark (layout "refined"): counts per part, times, peak memory, refinement 1..3.

Usage: python bench/mesh_bench.py [r1 r2 ...]   (default 1 2 3). Each refinement runs in its own
process so its peak memory (max RSS) is measured separately.
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORKER = r"""
import json, resource, sys, time
from railvib_hpc.config import load_case
from railvib_hpc.mesh.stage import make_mesh
t0 = time.perf_counter()
mesh, report = make_mesh(load_case(sys.argv[1], [f"mesh.refinement={sys.argv[2]}",
                                                 f"mesh.layout={sys.argv[3]}"]))
report["total_s"] = time.perf_counter() - t0
report["peak_rss_gb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6
print(json.dumps(report))
"""


def main(refinements: list[str]) -> None:
    case = ROOT / "jobs" / "thesis_baseline.toml"
    rows = []
    for r in refinements:
        t0 = time.perf_counter()
        # the README's refinement table is for the engineering layout (scales to 1.5 M nodes)
        out = subprocess.run([sys.executable, "-c", WORKER, str(case), r, "refined"], check=True,
                             capture_output=True, text=True).stdout
        rep = json.loads(out.strip().splitlines()[-1])
        rep["wall_s"] = time.perf_counter() - t0
        rows.append((r, rep))
    parts = list(rows[0][1]["elements_per_part"])
    print("| refinement | " + " | ".join(r for r, _ in rows) + " |")
    print("|---|" + "---|" * len(rows))

    def line(label, fn):
        print(f"| {label} | " + " | ".join(fn(rep) for _, rep in rows) + " |")

    line("nodes", lambda r: f"{r['quality']['n_nodes']:,}")
    line("DOF (3/node, upper bound)", lambda r: f"{3 * r['quality']['n_nodes']:,}")
    line("hexahedra", lambda r: f"{r['quality']['n_hexes']:,}")
    line("beam + pad elements", lambda r: f"{r['quality']['n_lines']:,}")
    for p in parts:
        line(f"elements `{p}`", lambda r, p=p: f"{r['elements_per_part'][p]:,}")
    line("min scaled Jacobian", lambda r: f"{r['quality']['min_scaled_jacobian']:.3f}")
    line("max aspect ratio", lambda r: f"{r['quality']['max_aspect_ratio']:.2f}")
    line("gmsh geometry + meshing [s]",
         lambda r: f"{r['timings']['geometry'] + r['timings']['meshing']:.2f}")
    line("quality checks [s]", lambda r: f"{r['timings']['quality']:.2f}")
    line("make_mesh total [s]", lambda r: f"{r['total_s']:.2f}")
    line("peak memory [GB]", lambda r: f"{r['peak_rss_gb']:.2f}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["1", "2", "3"])
