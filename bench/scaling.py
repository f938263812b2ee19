"""Strong scaling of every stage, and a time/memory estimate for 1M and 10M DOFs.

Usage::

    python bench/scaling.py [--ranks 1 2] [--case jobs/thesis_baseline.toml]
                            [--set key=value ...] [--launcher "mpirun --oversubscribe -n {n}"]
                            [--work DIR] [--keep]
                            [--from results/studies/convergence ...] [--estimate-only]
                            [--analyse 1.5 2]

**Scaling.** For each rank count it runs ``railvib run CASE`` (mesh, modal, mbs,
reconstruct, assess) in a fresh folder under the launcher (``{n}`` = ranks; on a cluster
e.g. ``--launcher "srun -n {n}"`` inside an allocation, ``--ranks 1 2 4 8 16``), reads the
run's ``run.json`` (:mod:`railvib_hpc.io.run_record`: wall time, parts and peak memory of
every rank per stage) and prints the time, speed-up and parallel efficiency per stage,
the peak memory per stage, plus the eigensolver's own breakdown from ``modes.h5``. The mesh
(gmsh), the MBS and the assessment run on rank 0 by design; modal (assembly, MUMPS,
Lanczos) and reconstruct are parallel.

**Estimate.** From every ``modes.h5`` found under the ``--from`` folders (default: the
mesh convergence study's levels, ``results/studies/convergence/*/``; same rank count and
mode count only) it fits power laws ``y = a N^b`` in the number of free DOFs N to MUMPS's
factor-memory estimate (INFOG(17)), the factorization time, the eigensolve time and the
peak memory, and extrapolates them to 1M and 10M DOFs; the Lanczos basis memory follows
exactly from the solver's rule, the field output of the reconstruct stage from the node
count. ``--analyse 1.5 2`` adds the factor-memory estimates of larger meshes from the
MUMPS analysis phase alone (mesh + assembly + analysis, no factorization: it fits where the
solve would not). Nothing that does not fit in memory is run.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import tomllib

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "jobs" / "thesis_baseline.toml"

#: The pipeline's stages, in order (the ``stages`` table of run.json).
GROUPS = ("mesh", "modal", "mbs", "reconstruct", "assess")


def read_run_json(out: Path) -> dict:
    """Per stage of ``<out>/run.json``: wall time, its timed parts, peak memory (all ranks).

    Raises
    ------
    RuntimeError
        When the run left no record of a stage.
    """
    from railvib_hpc.io.run_record import read_run_record

    record = read_run_record(out)
    if record is None:
        raise RuntimeError(f"{out}: no readable run.json")
    missing = [g for g in GROUPS if g not in record["stages"]]
    if missing:
        raise RuntimeError(f"{out}/run.json has no entry for {', '.join(missing)}")
    stages = {g: record["stages"][g] for g in GROUPS}
    return {"stages": {g: float(e["wall_s"]) for g, e in stages.items()},
            "raw": {f"{g}/{n}": float(t) for g, e in stages.items() for n, t in e["substages"]},
            "peak_gb": {g: float(e["peak_rss_gb_total"]) for g, e in stages.items()},
            "versions": stages["modal"]["versions"]}


def run_pipeline(n: int, case: Path, sets: list[str], launcher: str, work: Path,
                 keep: bool) -> dict:
    """``railvib run`` on ``n`` ranks in a fresh folder; timings, wall time, modal stats."""
    import h5py

    out = work / f"ranks{n}"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [*shlex.split(launcher.format(n=n)), sys.executable, "-m", "railvib_hpc", "run",
           str(case), "--out", str(out)]
    for s in sets:
        cmd += ["--set", s]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    print(f"# {' '.join(cmd)}", flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{n} ranks: exit {proc.returncode}\n{proc.stdout[-3000:]}\n"
                           f"{proc.stderr[-3000:]}")
    record = read_run_json(out)
    with h5py.File(out / "modes.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    fields = out / "fields.h5"
    size = fields.stat().st_size if fields.exists() else 0
    if not keep:
        shutil.rmtree(out, ignore_errors=True)
    return {"ranks": n, "wall": wall, **record, "stats": stats, "fields_bytes": size}


def scaling_table(runs: list[dict]) -> str:
    """Markdown table: seconds per stage and rank count, speed-up and efficiency."""
    base = runs[0]
    head = ["stage", *(f"{r['ranks']} rank(s) [s]" for r in runs),
            *(f"speed-up {r['ranks']}" for r in runs[1:]),
            *(f"efficiency {r['ranks']}" for r in runs[1:])]
    rows = []
    names = [*GROUPS, "sum of stages", "wall (incl. start-up)"]
    serial = {"mesh": "mesh (rank 0)", "mbs": "mbs (rank 0)", "assess": "assess (rank 0)"}
    for g in names:
        def t(r: dict, g: str = g) -> float:
            if g == "sum of stages":
                return sum(r["stages"].values())
            if g == "wall (incl. start-up)":
                return r["wall"]
            return r["stages"][g]
        t0 = t(base)
        sp = [t0 / t(r) if t(r) > 0 else math.nan for r in runs[1:]]
        eff = [s * base["ranks"] / r["ranks"] for s, r in zip(sp, runs[1:])]
        rows.append([serial.get(g, g), *(f"{t(r):.2f}" for r in runs),
                     *(f"{s:.2f}" for s in sp), *(f"{e:.2f}" for e in eff)])
    for key, label in (("time_factorization", "  MUMPS factorization"),
                       ("time_block_solves", "  block solves"),
                       ("time_orthogonalization", "  orthogonalization"),
                       ("time_purify_project", "  purification + Rayleigh-Ritz")):
        if all(key in r["stats"] for r in runs):
            vals = [r["stats"][key] for r in runs]
            sp = [vals[0] / v if v > 0 else math.nan for v in vals[1:]]
            eff = [s * base["ranks"] / r["ranks"] for s, r in zip(sp, runs[1:])]
            rows.append([label, *(f"{v:.2f}" for v in vals), *(f"{s:.2f}" for s in sp),
                         *(f"{e:.2f}" for e in eff)])
    for g in GROUPS:
        rows.append([f"peak memory of {g}, all ranks [GB]",
                     *(f"{r['peak_gb'][g]:.2f}" for r in runs),
                     *([""] * (2 * (len(runs) - 1)))])
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


# ---------------------------------------------------------------------------- estimate

#: Mesh + assembly + MUMPS analysis only (no factorization): the factor-memory estimate of
#: models too large to solve here. Run under the launcher; prints one JSON line on rank 0.
ANALYSIS_WORKER = r"""
import json, sys, time
from mpi4py import MPI
from railvib_hpc.petsc_env import init_petsc
init_petsc([])
from railvib_hpc.config import load_case
from railvib_hpc.mesh.stage import make_mesh
from railvib_hpc.model.dofmap import build_dofmap
from railvib_hpc.modal.eigen import PREFIX
from railvib_hpc.model.factor import ShiftInvertFactor
from railvib_hpc.model.petsc import assemble
from railvib_hpc.parallel import on_root
from railvib_hpc.problem import Problem
comm = MPI.COMM_WORLD
case = load_case(sys.argv[1], [f"mesh.refinement={sys.argv[2]}"])
t0 = time.perf_counter()
mesh = on_root(lambda: make_mesh(case)[0], comm)
dm = build_dofmap(mesh, comm.size, case["modal.fix_sleeper_rotations"],
                  case["modal.fix_rail_rotations_at_pads"])
K, M, _ = assemble(mesh, Problem.from_case(case), dm, comm)
op = ShiftInvertFactor.__new__(ShiftInvertFactor)      # analysis only: no factorization
op.A, op.comm, op.inertia = K, comm, False
gb = op._estimate_factor_memory(PREFIX)
if comm.rank == 0:
    print(json.dumps({"refinement": float(sys.argv[2]), "n_dofs": int(dm.n_dofs),
                      "n_nodes": int(mesh.n_nodes), "factor_gb": gb, "ranks": comm.size,
                      "seconds": time.perf_counter() - t0}))
"""


def analyse_refinement(case: Path, refinement: float, ranks: int, launcher: str) -> dict:
    """MUMPS factor-memory estimate (analysis phase only) of one refinement."""
    cmd = [*shlex.split(launcher.format(n=ranks)), sys.executable, "-c", ANALYSIS_WORKER,
           str(case), str(refinement)]
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    print(f"# MUMPS analysis only, refinement {refinement:g} on {ranks} rank(s)", flush=True)
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"analysis of refinement {refinement}: exit {proc.returncode}\n"
                           f"{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}")
    return json.loads(lines[-1])


def collect_levels(folders: list[Path]) -> list[dict]:
    """Modal statistics of every complete ``modes.h5`` under the folders (one level each)."""
    import h5py

    out = []
    for folder in folders:
        for path in sorted(folder.glob("*/modes.h5")) + sorted(folder.glob("modes.h5")):
            try:
                with h5py.File(path, "r") as f:
                    if int(f.attrs.get("complete", 0)) != 1:
                        continue
                    stats = json.loads(f.attrs["stats"])
                    case = tomllib.loads(str(f.attrs["case_toml"]))
                    n_nodes = int(f["mesh/points"].shape[0])
                    m = int(f["modes/eigenvalue"].shape[0])
            except (OSError, KeyError, ValueError):
                continue
            if "factor_memory_gb" not in stats:
                continue
            out.append({"path": str(path), "n_dofs": int(stats["n_dofs"]), "n_nodes": n_nodes,
                        "n_modes": m, "ranks": int(stats.get("ranks", 0)),
                        "refinement": float(case["mesh"]["refinement"]),
                        "domain": case.get("domain", {}),
                        "factor_gb": float(stats["factor_memory_gb"]),
                        "t_factor": float(stats["time_factorization"]),
                        "t_eigen": float(stats["time_solve"]),
                        "peak_gb": float(stats["peak_rss_gb_total"]),
                        "t_solves": float(stats.get("time_block_solves", 0.0)),
                        "t_orth": float(stats.get("time_orthogonalization", 0.0))})
    return out


def fit_power(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Least-squares fit ``y = a x^b`` in log-log; returns (a, b)."""
    b, loga = np.polyfit(np.log(x), np.log(y), 1)
    return float(np.exp(loga)), float(b)


def basis_gb(n: float, m: int = 300, block: int = 32) -> float:
    """Lanczos basis memory [GB] by the modal stage's rule (basis capped at 4 GB)."""
    cap = int(4e9 / (8.0 * n))
    basis = max(min(3 * m, cap), m + 3 * block)
    return 8.0 * n * (basis + 3 * block + m) / 1e9


def components_gb(n: float, factor_gb: float, m: int = 300, block: int = 32) -> float:
    """In-core memory the modal stage needs by construction [GB, all ranks]: the MUMPS factor,
    the Lanczos basis and the three eigenvector blocks of the purification (X, KX, MX)."""
    return factor_gb + basis_gb(n, m, block) + 3 * 8.0 * n * m / 1e9


def estimate(levels: list[dict], analysed: list[dict] | None = None, targets=(1e6, 1e7),
             steps: int = 921) -> str:
    """Fits and extrapolations as printable text (markdown tables).

    Parameters
    ----------
    levels
        Solved models (:func:`collect_levels`); those with domain extensions join the fits
        in N but not the DOFs-vs-refinement fit.
    analysed
        Factor-memory estimates of larger models (MUMPS analysis only); they join the
        factor-memory fit and the DOFs-vs-refinement fit.
    targets
        DOF counts to extrapolate to.
    steps
        Stored steps of the reconstructed fields (thesis: 921).
    """
    if len(levels) < 3:
        return ("estimate: need at least 3 levels with modal statistics (run the mesh "
                "convergence study first: railvib study convergence "
                "jobs/mesh_convergence.toml --out results/studies)")
    key = max({(lv["ranks"], lv["n_modes"]) for lv in levels},
              key=lambda k: sum((lv["ranks"], lv["n_modes"]) == k for lv in levels))
    pts = sorted((lv for lv in levels if (lv["ranks"], lv["n_modes"]) == key),
                 key=lambda lv: lv["n_dofs"])
    if len(pts) < 3:
        return "estimate: fewer than 3 comparable levels (same ranks and modes)"
    m = key[1]
    n = np.array([p["n_dofs"] for p in pts], dtype=float)

    def label(p: dict) -> str:
        d = p["domain"]
        ext = "" if not any(d.values()) else (
            f" +{d.get('extra_depth', 0):g}/{d.get('extra_length', 0):g}/"
            f"{d.get('extra_width', 0):g} m")
        return f"{p['refinement']:g}{ext}"

    lines = [f"Measured models ({key[0]} rank(s), {m} modes, block Lanczos + MUMPS; "
             "domain extensions as +depth/length/width):", "",
             "| refinement | DOFs | MUMPS factor estimate [GB] | factorization [s] | "
             "eigensolve [s] | peak memory, all ranks [GB] | factor + basis + eigenvector "
             "blocks [GB] | peak / that |", "|---|---|---|---|---|---|---|---|"]
    overhead = []
    for p in pts:
        c = components_gb(p["n_dofs"], p["factor_gb"], m)
        overhead.append(p["peak_gb"] / c)
        lines.append(f"| {label(p)} | {p['n_dofs']:,} | {p['factor_gb']:.2f} | "
                     f"{p['t_factor']:.1f} | {p['t_eigen']:.1f} | {p['peak_gb']:.2f} | "
                     f"{c:.2f} | {overhead[-1]:.2f} |")
    for p in pts:
        p["t_rest"] = max(p["t_eigen"] - p["t_solves"] - p["t_orth"], 1e-3)
    fits = {k: fit_power(n, np.array([p[k] for p in pts])) for k in
            ("factor_gb", "t_factor", "t_eigen", "peak_gb", "t_solves", "t_orth", "t_rest")}
    extra = [a for a in (analysed or []) if a["ranks"] == key[0]]
    plain = [p for p in pts if not any(p["domain"].values())]
    ref_pts = [(p["refinement"], p["n_dofs"]) for p in plain]
    if extra:
        lines += ["", "MUMPS analysis only (mesh + assembly + analysis, no factorization; "
                  "INFOG(17)):", "",
                  "| refinement | DOFs | MUMPS factor estimate [GB] | fit of the solved models "
                  "[GB] |", "|---|---|---|---|"]
        a0, b0 = fits["factor_gb"]
        lines += [f"| {a['refinement']:g} | {a['n_dofs']:,} | {a['factor_gb']:.2f} | "
                  f"{a0 * a['n_dofs'] ** b0:.2f} |" for a in extra]
        nn = np.concatenate([n, [a["n_dofs"] for a in extra]])
        ff = np.concatenate([[p["factor_gb"] for p in pts], [a["factor_gb"] for a in extra]])
        fits["factor_gb"] = fit_power(nn, ff)
        ref_pts += [(a["refinement"], a["n_dofs"]) for a in extra]
    a_ref, b_ref = fit_power(np.array([r for r, _ in ref_pts]),
                             np.array([d for _, d in ref_pts], dtype=float))
    nodes_per_dof = float(np.mean([p["n_nodes"] / p["n_dofs"] for p in pts]))
    over = max(overhead)
    lines += ["", "Power-law fits y = a N^b (N = free DOFs):", "",
              "| quantity | exponent b | note |", "|---|---|---|",
              f"| MUMPS factor memory | {fits['factor_gb'][1]:.2f} | nested dissection in 3-D: "
              "theory ~N^4/3" + (" (incl. the analysed models)" if extra else "") + " |",
              f"| factorization time | {fits['t_factor'][1]:.2f} | theory ~N^2 (flops), less "
              "while memory-bound |",
              f"| eigensolve time ({m} modes) | {fits['t_eigen'][1]:.2f} | for comparison; "
              "the estimate below sums its parts |",
              f"| - block solves | {fits['t_solves'][1]:.2f} | ~ factor size |",
              f"| - orthogonalization | {fits['t_orth'][1]:.2f} | ~ N x basis^2 |",
              f"| - the rest (purification, Rayleigh-Ritz, products) | {fits['t_rest'][1]:.2f} "
              "| |",
              f"| peak memory | {fits['peak_gb'][1]:.2f} | for comparison; the estimate "
              "below uses the components |",
              f"| DOFs vs refinement | {b_ref:.2f} | N = {a_ref:,.0f} r^{b_ref:.2f} |"]
    lines += ["", f"Extrapolation ({key[0]} rank(s) of this machine, {m} modes; peak memory = "
              f"(factor + basis + eigenvector blocks) x {over:.2f}, the largest measured "
              f"ratio; fields: {steps} steps, float64):", "",
              "| DOFs | refinement | MUMPS factor [GB] | Lanczos basis [GB] | eigenvector "
              "blocks [GB] | peak memory [GB] | factorization [s] | eigensolve [s] | "
              "fields.h5 [GB] |", "|---|---|---|---|---|---|---|---|---|"]
    for t in targets:
        r = (t / a_ref) ** (1.0 / b_ref)
        f = {k: a * t**b for k, (a, b) in fits.items()}
        f["t_eigen"] = f["t_solves"] + f["t_orth"] + f["t_rest"]
        blocks = 3 * 8.0 * t * m / 1e9
        peak = over * components_gb(t, f["factor_gb"], m)
        fields = 3 * 3 * 8 * t * nodes_per_dof * steps / 1e9
        lines.append(f"| {t:,.0f} | {r:.2f} | {f['factor_gb']:.1f} | {basis_gb(t, m):.1f} | "
                     f"{blocks:.1f} | {peak:.0f} | {f['t_factor']:.0f} | "
                     f"{f['t_eigen']:,.0f} ({f['t_eigen'] / 3600:.1f} h) | {fields:.0f} |")
    lines += ["", "Memory is the sum over the ranks: the factor, the basis and the eigenvector "
              "blocks are distributed, the mesh (~100 B/node) is replicated on every rank. The "
              "basis is capped at 4 GB (fewer vectors at large N: more restarts, so the "
              "eigensolve time is a lower bound there). Time is for the rank count above; the "
              "scaling table gives the parallel efficiency of each part."]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    p.add_argument("--case", type=Path, default=CASE)
    p.add_argument("--set", dest="sets", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--launcher", default="mpirun --oversubscribe -n {n}",
                   help="command prefix, {n} = ranks (e.g. 'srun -n {n}')")
    p.add_argument("--work", type=Path, default=None, help="scratch folder (default: temp)")
    p.add_argument("--keep", action="store_true", help="keep the run folders")
    p.add_argument("--from", dest="sources", type=Path, nargs="+",
                   default=[ROOT / "results" / "studies" / "convergence"],
                   help="folders with <level>/modes.h5 for the estimate (e.g. also "
                        "results/studies/reflection: larger domains)")
    p.add_argument("--estimate-only", action="store_true")
    p.add_argument("--analyse", type=float, nargs="*", default=[], metavar="REFINEMENT",
                   help="refinements too large to solve: MUMPS analysis only (factor "
                        "memory), added to the memory fit")
    p.add_argument("--analyse-ranks", type=int, default=2)
    p.add_argument("--json", type=Path, default=None, help="also write the numbers here")
    args = p.parse_args(argv)
    report: dict = {}
    if not args.estimate_only:
        work = args.work or Path(tempfile.mkdtemp(prefix="railvib-scaling-"))
        work.mkdir(parents=True, exist_ok=True)
        runs = [run_pipeline(n, args.case, args.sets, args.launcher, work, args.keep)
                for n in args.ranks]
        print(f"\nStrong scaling, {args.case.name} "
              + (f"({', '.join(args.sets)})" if args.sets else "")
              + f", {runs[0]['stats'].get('n_dofs', 0):,} DOFs, "
              f"fields.h5 {runs[0]['fields_bytes'] / 1e9:.2f} GB:\n")
        print(scaling_table(runs))
        report["runs"] = runs
    levels = collect_levels(args.sources)
    analysed = [analyse_refinement(args.case, r, args.analyse_ranks, args.launcher)
                for r in args.analyse]
    print("\n" + estimate(levels, analysed))
    report["levels"] = levels
    report["analysed"] = analysed
    if args.json:
        args.json.write_text(json.dumps(report, indent=1, default=float))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
