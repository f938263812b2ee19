"""Benchmark: ``railvib transient`` on the thesis model vs the modal pipeline (issue 12, step 6).

Usage (heavy: run under the lock; not a test)::

    flock /tmp/railvib-heavy.lock .venv/bin/python bench/transient_bench.py \\
        jobs/thesis_baseline.toml results/bench_transient [--ranks 2] [--modes 300] \\
        [--set KEY=VALUE ...]

Runs from scratch (fresh output folders):

1. ``mpirun -n RANKS railvib transient CASE``: the full-order passage (mesh, assembly,
   factorization, time integration, fields, stresses, probes, assessment);
2. ``mpirun -n RANKS railvib run CASE --set modal.n_modes=MODES`` (+ ``--modal-set``): the
   modal pipeline (mesh, eigensolve, multibody, reconstruction, assessment) to compare.

Prints the stage timings of both (from each folder's ``run.json``), steps per second, wall
time of the passage and the peak memory (sum over ranks, ``/usr/bin/time -v``); target: the
passage within 15 minutes on 2 ranks at thesis size. JSON in ``OUT/bench.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = str(ROOT / ".venv" / "bin" / "python")
TARGET_S = 15 * 60


def run(cmd: list[str], log: Path, out: Path) -> dict:
    """Run ``cmd`` under ``/usr/bin/time -v``: wall seconds, peak RSS of the whole command
    (GB, all processes) and the stage timings from ``<out>/run.json`` (each stage's wall
    time and its timed parts, ``"<stage>: <part>"``; each stage's own peak memory)."""
    from railvib_hpc.io.run_record import read_run_record

    t0 = time.perf_counter()
    env = {**os.environ, "OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1"}
    with open(log, "w") as f:
        rc = subprocess.run(["/usr/bin/time", "-v", *cmd], stdout=f, stderr=subprocess.STDOUT,
                            env=env).returncode
    wall = time.perf_counter() - t0
    if rc != 0:
        sys.exit(f"failed ({rc}): {' '.join(cmd)}; see {log}")
    rss = sum(int(x) for x in re.findall(r"Maximum resident set size \(kbytes\): (\d+)",
                                         log.read_text()))
    record = read_run_record(out)
    if record is None:
        sys.exit(f"{out}/run.json is missing or unreadable after: {' '.join(cmd)}")
    stages, stage_rss = {}, {}
    for name, entry in record["stages"].items():
        stages[name] = float(entry["wall_s"])
        for part, seconds in entry.get("substages", []):
            stages[f"{name}: {part}"] = float(seconds)
        stage_rss[name] = entry.get("peak_rss_gb_total")
    return {"wall_s": wall, "peak_rss_gb": rss / 1e6, "stages": stages,
            "stage_peak_rss_gb": stage_rss}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("case")
    p.add_argument("out", type=Path)
    p.add_argument("--ranks", type=int, default=2)
    p.add_argument("--modes", type=int, default=300)
    p.add_argument("--set", dest="overrides", action="append", default=[])
    p.add_argument("--modal-set", dest="modal_overrides", action="append", default=[],
                   help="extra overrides of the modal run only (e.g. mbs.static_correction=true)")
    args = p.parse_args()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    sets = [x for s in args.overrides for x in ("--set", s)]
    mpi = ["mpirun", "--oversubscribe", "-n", str(args.ranks), PY, "-m", "railvib_hpc"]
    for d in ("transient", "modal"):
        subprocess.run(["rm", "-rf", str(out / d)], check=True)
    direct = run([*mpi, "transient", args.case, "--out", str(out / "transient"), *sets],
                 out / "transient.log", out / "transient")
    import h5py

    with h5py.File(out / "transient" / "transient.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    modal = run([*mpi, "run", args.case, "--out", str(out / "modal"), *sets, "--set",
                 f"modal.n_modes={args.modes}",
                 *[x for s in args.modal_overrides for x in ("--set", s)]], out / "modal.log",
                out / "modal")
    result = {"direct": {**direct, "stats": stats}, "modal": modal, "ranks": args.ranks,
              "modes": args.modes, "case": args.case, "overrides": args.overrides}
    (out / "bench.json").write_text(json.dumps(result, indent=1))

    s = stats
    print(f"railvib transient, {s['n_dofs']:,} DOFs on {args.ranks} rank(s): dt {s['dt']:.3e} s, "
          f"{s['n_steps']} steps to {s['t_end']:.3f} s")
    print(f"  time integration {s['time_integration']:.1f} s = {s['steps_per_second']:.2f} "
          f"steps/s (solves {s['time_solves']:.1f} s, products {s['time_products']:.1f} s, "
          f"contact {s['time_contact']:.1f} s incl. {s.get('rail_columns', 0)} rail columns "
          f"in {s.get('time_rail_columns', 0.0):.1f} s), factorization "
          f"{s['time_factorization']:.1f} s, factor {s['factor_memory_gb']:.2f} GB")
    print(f"  wall {direct['wall_s']:.1f} s (target <= {TARGET_S} s: "
          f"{'met' if direct['wall_s'] <= TARGET_S else 'NOT met'}), peak memory "
          f"{direct['peak_rss_gb']:.2f} GB (all ranks)")
    print(f"railvib run (modal pipeline, {args.modes} modes): wall {modal['wall_s']:.1f} s, peak "
          f"memory {modal['peak_rss_gb']:.2f} GB")
    print("\n| stage | transient [s] | modal pipeline [s] |")
    print("|---|---|---|")
    for name in sorted(set(direct["stages"]) | set(modal["stages"]),
                       key=lambda n: (n == "total", n)):
        a, b = direct["stages"].get(name), modal["stages"].get(name)
        print(f"| {name} | {'' if a is None else f'{a:.1f}'} | "
              f"{'' if b is None else f'{b:.1f}'} |")
    print(f"| wall (whole command) | {direct['wall_s']:.1f} | {modal['wall_s']:.1f} |")
    print(f"| peak memory, all ranks [GB] | {direct['peak_rss_gb']:.2f} | "
          f"{modal['peak_rss_gb']:.2f} |")


if __name__ == "__main__":
    main()
