"""Modal benchmark: the thesis baseline on 1 and 2 ranks, against scipy's eigsh.

Usage::

    python bench/modal_bench.py [--refinements 1 2] [--ranks 1 2] [--modes 300]
                                [--scipy-refinements 1] [--scipy-timeout 3600]

For every (refinement, ranks) pair it runs ``railvib modal`` under mpirun in a fresh output
folder with ``-log_view`` and prints DOFs, assembly, factorization, eigensolve and wall
times, right-hand sides solved and peak memory (from ``modes.h5``). For the refinements in
``--scipy-refinements`` it then assembles the same K and M serially and times
``scipy.sparse.linalg.eigsh(K, k, M, sigma=0)`` (SuperLU shift-invert + ARPACK) in a separate
process, and prints the time ratio and the largest eigenvalue difference.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CASE = ROOT / "jobs" / "thesis_baseline.toml"

SCIPY_WORKER = r"""
import json, resource, sys, time
import numpy as np, scipy.sparse as sp
from scipy.sparse.linalg import eigsh
from railvib_hpc.config import load_case
from railvib_hpc.mesh.stage import make_mesh
from railvib_hpc.model.dofmap import build_dofmap
from railvib_hpc.model.petsc import assemble
from railvib_hpc.petsc_env import init_petsc
from railvib_hpc.problem import Problem
from mpi4py import MPI
init_petsc([])
case = load_case(sys.argv[1], [f"mesh.refinement={sys.argv[2]}"])
mesh, _ = make_mesh(case)
dm = build_dofmap(mesh, 1)
t0 = time.perf_counter()
Kp, Mp, _ = assemble(mesh, Problem.from_case(case), dm, MPI.COMM_SELF)
n = dm.n_dofs
K = sp.csr_matrix(Kp.getValuesCSR()[::-1], shape=(n, n))
M = sp.csr_matrix(Mp.getValuesCSR()[::-1], shape=(n, n))
Kp.destroy(); Mp.destroy()
t1 = time.perf_counter()
lam = eigsh(K, k=int(sys.argv[3]), M=M, sigma=0.0, which="LM", tol=1e-8,
            return_eigenvectors=True)[0]
t2 = time.perf_counter()
print(json.dumps({"assembly": t1 - t0, "eigsh": t2 - t1, "eigenvalues": sorted(lam.tolist()),
                  "peak_rss_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1e6}))
"""


def run_modal(refinement: str, ranks: int, modes: int) -> dict:
    out = Path(tempfile.mkdtemp(prefix=f"railvib-bench-r{refinement}-n{ranks}-"))
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), sys.executable, "-m", "railvib_hpc",
           "modal", str(CASE), "--set", f"mesh.refinement={refinement}", "--set",
           f"modal.n_modes={modes}", "--out", str(out), "--", "-log_view",
           f":{out / 'log_view.txt'}"]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        lines = [ln for ln in proc.stderr.splitlines() if "error:" in ln] or \
            proc.stderr.strip().splitlines()[-1:]
        shutil.rmtree(out, ignore_errors=True)
        return {"error": lines[0] if lines else f"exit code {proc.returncode}", "wall": wall}
    with h5py.File(out / "modes.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
        stats["eigenvalues"] = f["modes/eigenvalue"][()].tolist()
        stats["f_range"] = (float(f["modes/frequency_hz"][0]), float(f["modes/frequency_hz"][-1]))
        stats["n_nodes"] = int(f["mesh/points"].shape[0])
        stats["n_hexes"] = int(f["mesh/hexes"].shape[0])
    stats["wall"] = wall
    stats["stage_times"] = _stage_times(out)
    shutil.rmtree(out, ignore_errors=True)
    return stats


def _stage_times(out: Path) -> dict[str, float]:
    """The modal stage's timed parts and its total, from ``<out>/run.json``."""
    from railvib_hpc.io.run_record import read_run_record

    entry = (read_run_record(out) or {}).get("stages", {}).get("modal")
    if entry is None:
        raise RuntimeError(f"{out}/run.json has no modal entry")
    return {**{n: float(t) for n, t in entry["substages"]}, "modal": float(entry["wall_s"])}


def run_scipy(refinement: str, modes: int, timeout: float) -> dict:
    cmd = [sys.executable, "-c", SCIPY_WORKER, str(CASE), refinement, str(modes)]
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, check=False)
    except subprocess.TimeoutExpired:
        return {"error": f"did not finish within {timeout:.0f} s"}
    if proc.returncode != 0:
        return {"error": proc.stderr[-1000:]}
    res = json.loads(proc.stdout.strip().splitlines()[-1])
    res["wall"] = time.perf_counter() - t0
    return res


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--refinements", nargs="+", default=["1", "2"])
    ap.add_argument("--ranks", nargs="+", type=int, default=[1, 2])
    ap.add_argument("--modes", type=int, default=300)
    ap.add_argument("--scipy-refinements", nargs="*", default=["1"])
    ap.add_argument("--scipy-timeout", type=float, default=3600.0)
    args = ap.parse_args()
    rows = []
    for r in args.refinements:
        for n in args.ranks:
            print(f"running refinement {r} on {n} rank(s) ...", flush=True)
            rows.append((r, n, run_modal(r, n, args.modes)))
    print()
    print("| refinement | ranks | nodes | DOFs | hexes | assembly [s] | hex/s/rank | "
          "factorization [s] | eigensolve [s] | RHS solved | block solves [s] | "
          "orthogonalization [s] | wall [s] | peak memory [GB] | frequencies [Hz] |")
    print("|" + "---|" * 15)
    for r, n, s in rows:
        if "error" in s:
            print(f"| {r} | {n} | failed after {s['wall']:.0f} s: {s['error'].strip()} |")
            continue
        rate = s.get("assembly_local_hexes", s["n_hexes"] / n) / s["time_assembly_total"]
        print(f"| {r} | {n} | {s['n_nodes']:,} | {s['n_dofs']:,} | {s['n_hexes']:,} | "
              f"{s['time_assembly_total']:.2f} | {rate:,.0f} | {s['time_factorization']:.2f} | "
              f"{s['time_solve']:.1f} | {s['linear_solves']} | "
              f"{s.get('time_block_solves', float('nan')):.1f} | "
              f"{s.get('time_orthogonalization', float('nan')):.1f} | {s['wall']:.1f} | "
              f"{s['peak_rss_gb_total']:.2f} | {s['f_range'][0]:.3f}-{s['f_range'][1]:.3f} |")
    for r in args.scipy_refinements:
        print(f"\nscipy eigsh (SuperLU shift-invert + ARPACK), refinement {r}, serial ...",
              flush=True)
        sc = run_scipy(r, args.modes, args.scipy_timeout)
        if "error" in sc:
            print(f"  scipy: {sc['error']}")
            continue
        print(f"  scipy: assembly {sc['assembly']:.2f} s, eigsh {sc['eigsh']:.1f} s, peak "
              f"{sc['peak_rss_gb']:.2f} GB")
        for rr, n, s in rows:
            if rr == r and "error" not in s:
                ours = np.array(s["eigenvalues"])
                theirs = np.array(sc["eigenvalues"])
                diff = np.max(np.abs(ours - theirs) / theirs)
                print(f"  railvib on {n} rank(s): eigensolve {s['time_solve']:.1f} s + "
                      f"factorization {s['time_factorization']:.1f} s -> eigsh / railvib = "
                      f"{sc['eigsh'] / (s['time_solve'] + s['time_factorization']):.2f}x; "
                      f"max relative eigenvalue difference {diff:.2e}")


if __name__ == "__main__":
    main()
