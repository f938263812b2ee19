"""Band-sliced eigensolve benchmark (issue 14's table): one ``railvib modal`` run per line.

Usage (every heavy run under the shared lock)::

    flock /tmp/railvib-heavy.lock python bench/band_bench.py --ranks 2 --f-max 65 \\
        --bands 1 2 4 8            # (c): the split's effect; --bands 0 = automatic (a)
    flock /tmp/railvib-heavy.lock python bench/band_bench.py --ranks 2 --f-max 65 \\
        --groups 2                 # (a) with 2 bands at a time on 1 rank each
    flock /tmp/railvib-heavy.lock python bench/band_bench.py --refinement 2 --f-max 42.2
    flock /tmp/railvib-heavy.lock python bench/band_bench.py --f-max 65 \\
        --reference slepc-slicing single-shift     # (d): SLEPc and one shift, same matrix

Each configuration runs in a fresh process (so that peak memory is its own) under mpirun
with a fresh output folder; printed: modes, bands, wall time of the command, eigensolve
time, factorisations, right-hand sides, orthogonalisation, the merge, max |Phi^T M Phi - I|,
max relative residual, peak memory summed over the ranks (the processes' life) and the
memory predictor's value (largest band: resident memory + K - sigma M and MUMPS's copy of
it + MUMPS estimate + dense arrays; merge: candidates + modes), and
the largest relative eigenvalue difference to the first configuration. Per band (comment
lines): the resident memory before it, its own peak (``VmHWM`` since its start), the
predictor, the resident memory after it is freed and the peak so far.

A second table splits each run's eigensolve into its phases (bands summed; issue 26):
all block solves (Lanczos and purification), orthogonalisation (Gram-Schmidt, thick
restarts, Ritz vectors), Lanczos's Rayleigh-Ritz convergence tests (and how many), the
purification's K and M products and solve residuals, the final Rayleigh-Ritz step
(projection, dense eigenproblem, rotation), the checks (``normalise_and_check``: K Phi and
M Phi afresh, orthonormality, residuals, round-off floors; since the fourth round of issue
26 also the first pass over the Ritz vectors as block Lanczos returns them, whose K and M
products were "purification" before) and the share of the last four
in the eigensolve; then the purification's solves (inside "solves") and the whole time
after the Lanczos phase (``time_purify_project``: purification with its solves, Rayleigh-
Ritz, checks; bands summed, the merge added) and its share of the eigensolve. The load
average (``/proc/loadavg``) before and after each run goes with it: other processes on the
cores slow every phase.
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
#: ``modal.band_modes`` that makes the automatic split one band (more modes than any run has)
ONE_BAND_MODES = 10**7


def loadavg() -> str:
    """The 1-minute load average (``/proc/loadavg``), or "?"."""
    try:
        return Path("/proc/loadavg").read_text().split()[0]
    except OSError:
        return "?"


#: The phase columns of the second table: (heading, statistics summed over the bands).
PHASES = (("solves [s]", ("time_block_solves",)),
          ("orthogonalisation [s]", ("time_orthogonalization",)),
          ("Lanczos RR [s]", ("time_lanczos_ritz",)),
          ("purification [s]", ("time_purify_products",)),
          ("final RR [s]", ("time_rayleigh_ritz",)),
          ("checks [s]", ("time_checks",)))


def phase_row(name: str, r: dict) -> str:
    """The second table's row: the eigensolve's phases (bands summed, the merge's Rayleigh-
    Ritz step and checks added)."""
    if "error" in r:
        return f"| {name} | failed |"
    st = r["stats"]
    parts = [b["stats"] for b in st.get("bands", [])] or [st]

    def total(keys) -> float:
        return float(sum(p.get(k, 0.0) for p in parts for k in keys))

    cols = [total(keys) for _, keys in PHASES]
    if not st.get("bands"):           # one shift: time_block_solves is the Lanczos's only
        cols[0] += st.get("time_purify_solves", 0.0)
    if st.get("bands"):                                  # the merge: its RR and its checks
        cols[4] += st.get("time_merge_rayleigh_ritz", 0.0)
        cols[5] += st.get("time_checks", 0.0)
    tests = int(total(("lanczos_ritz_steps",)))
    eig = st.get("time_solve", 0.0)
    share = sum(cols[2:]) / eig if eig else float("nan")
    # everything after the Lanczos phase (purification's solves included; with bands the
    # merge's Rayleigh-Ritz step and checks)
    after = total(("time_purify_project",))
    if st.get("bands"):
        after += st.get("time_merge_rayleigh_ritz", 0.0) + st.get("time_checks", 0.0)
    purify_solves = total(("time_purify_solves",))
    body = " | ".join(f"{c:.1f}" for c in cols)
    return (f"| {name} | {eig:.1f} | {body} | {tests} | {100 * share:.1f} % | "
            f"{purify_solves:.1f} | {after:.1f} ({100 * after / eig if eig else 0:.1f} %) | "
            f"{r.get('silence_s', float('nan')):.1f} | {r.get('load', '?')} |")


def run(out: Path, ranks: int, sets: list[str], petsc: list[str], timeout: float) -> dict:
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    cmd = ["mpirun", "--oversubscribe", "-n", str(ranks), sys.executable, "-m", "railvib_hpc",
           "modal", str(CASE), "--out", str(out)]
    for s in sets:
        cmd += ["--set", s]
    if petsc:
        cmd += ["--", *petsc]
    t0 = time.perf_counter()
    load0 = loadavg()
    proc, lines = run_timed(cmd, env, timeout)
    wall = time.perf_counter() - t0
    load = f"{load0} / {loadavg()}"
    if proc.returncode != 0:
        return {"error": (proc.stderr.strip().splitlines() or ["?"])[-1], "wall": wall,
                "load": load}
    with h5py.File(out / "modes.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
        lam = f["modes/eigenvalue"][()]
    progress = [ln for ln in proc.stdout.splitlines() if "ETA" in ln]
    return {"wall": wall, "stats": stats, "lam": lam, "progress_lines": len(progress),
            "last_progress": progress[-1].strip() if progress else "", "load": load,
            "silence_s": longest_silence(lines)}


def run_timed(cmd: list[str], env: dict, timeout: float):
    """Run ``cmd``; returns the completed process (stdout, stderr as text) and the stdout
    lines with their arrival times."""
    import threading

    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, bufsize=1)
    lines: list[tuple[float, str]] = []
    err: list[str] = []
    reader = threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True)
    reader.start()
    timer = threading.Timer(timeout, proc.kill)
    timer.start()
    try:
        for ln in proc.stdout:
            lines.append((time.perf_counter(), ln.rstrip("\n")))
        proc.wait()
    finally:
        timer.cancel()
    reader.join()
    return (subprocess.CompletedProcess(cmd, proc.returncode, "\n".join(ln for _, ln in lines),
                                        "".join(err)), lines)


def longest_silence(lines: list[tuple[float, str]]) -> float:
    """The longest gap [s] between two output lines (``(time, line)``, as they arrived)
    from "[eigensolve] ..." to its "done" line: what a user watches in silence."""
    inside = [t for t, ln in lines if "[eigensolve]" in ln]
    if len(inside) < 2:
        return float("nan")
    ts = [t for t, _ in lines if inside[0] <= t <= inside[-1]]
    return max((b - a for a, b in zip(ts, ts[1:])), default=0.0)


def row(name: str, r: dict, ref: np.ndarray | None) -> str:
    if "error" in r:
        return f"| {name} | failed after {r['wall']:.0f} s: {r['error']} |"
    st, lam = r["stats"], r["lam"]
    bands = st.get("bands", [])
    pred = max([b["stats"].get("predicted_peak_gb", 0.0) for b in bands] or
               [st.get("factor_memory_gb", 0.0)])
    merge = st.get("merge_predicted_gb")
    orth = sum(b["stats"].get("time_orthogonalization", 0.0) for b in bands) or \
        st.get("time_orthogonalization", 0.0)
    diff = ""
    if ref is not None and len(ref) == len(lam):
        diff = f"{np.abs(lam / ref - 1).max():.1e}"
    elif ref is not None:
        diff = f"{len(lam)} vs {len(ref)} modes"
    f = np.sqrt(lam) / (2 * np.pi)
    return (f"| {name} | {st.get('n_dofs', 0):,} | {len(lam)} ({f[0]:.3f}-{f[-1]:.3f} Hz) | "
            f"{st.get('n_bands', 1)} | {r['wall']:.1f} | {st.get('time_solve', 0.0):.1f} | "
            f"{st.get('time_factorization', 0.0):.1f} | {st.get('linear_solves', 0)} | "
            f"{orth:.1f} | {st.get('time_merge_rayleigh_ritz', 0.0):.1f} | "
            f"{st['max_orthonormality_error']:.1e} | {st['max_relative_residual']:.1e} | "
            f"{st['peak_rss_gb_total']:.2f} | {pred:.1f}"
            f"{'' if merge is None else f' / {merge:.1f}'} | {diff} |")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ranks", type=int, default=2)
    ap.add_argument("--refinement", type=float, default=1.0)
    ap.add_argument("--f-max", type=float, default=65.0)
    ap.add_argument("--bands", type=int, nargs="*", default=[0],
                    help="numbers of bands (Weyl split); 0 = automatic (modal.band_modes)")
    ap.add_argument("--groups", type=int, default=1)
    ap.add_argument("--reference", nargs="*", default=[],
                    choices=["slepc-slicing", "single-shift", "krylovschur", "eigsh"],
                    help="reference solvers on the same matrix; eigsh = scipy's ARPACK with "
                         "SuperLU shift-invert, serial (bench/modal_bench.py's worker), for the "
                         "mode count of the first run")
    ap.add_argument("--n-modes", type=int, default=0,
                    help="the mode count of the reference solvers when no band run gives it "
                         "(with --bands and no value: only the references run)")
    ap.add_argument("--set", action="append", default=[], dest="extra")
    ap.add_argument("--petsc", nargs="*", default=[])
    ap.add_argument("--timeout", type=float, default=3600)
    ap.add_argument("--json", default="", help="append one JSON line per run (for the "
                                                 "scaling model, bench/band_scaling_model.py)")
    args = ap.parse_args()
    from railvib_hpc.modal.bands import weyl_edges

    base = [f"mesh.refinement={args.refinement!r}", "modal.hex_formulation=bbar", *args.extra]
    configs = []
    for nb in args.bands:
        sets = [*base, f"modal.f_max={args.f_max!r}", f"modal.band_groups={args.groups}"]
        if nb == 1:
            # no inner edges would mean "automatic" (modal.band_modes per band): one band
            # is asked for by a band_modes above any mode count
            sets.append(f"modal.band_modes={ONE_BAND_MODES}")
        elif nb > 1:
            edges = weyl_edges(0.0, args.f_max, nb)
            sets.append(f"modal.bands={json.dumps(edges)}")
        configs.append((f"bands {'auto' if nb == 0 else nb}, groups {args.groups}", sets))
    ref_counts = args.n_modes or None
    for ref in args.reference:
        if ref == "eigsh":
            continue                      # run after the PETSc configurations, below
        if ref == "slepc-slicing":
            configs.append(("SLEPc spectrum slicing", [*base, f"modal.f_max={args.f_max!r}",
                                                       "modal.method=krylovschur"]))
        else:
            method = "block_lanczos" if ref == "single-shift" else "krylovschur"
            configs.append((ref, [*base, "modal.f_max=0", "modal.n_modes=@N",
                                  f"modal.method={method}"]))
    print(f"# {args.ranks} rank(s), refinement {args.refinement}, f_max {args.f_max} Hz, "
          f"{os.cpu_count()} cores")
    print("| run | DOFs | modes | bands | wall [s] | eigensolve [s] | factorisations [s] | "
          "RHS | orthogonalisation [s] | merge RR [s] | max abs(PhiTMPhi-I) | max rel. residual | "
          "peak [GB] | predicted [GB] (band / merge) | max rel. eigenvalue diff. |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    ref_lam = None
    phase_rows = []
    for name, sets in configs:
        if ref_counts is not None:
            sets = [s.replace("@N", str(ref_counts)) for s in sets]
        out = Path(tempfile.mkdtemp(prefix="railvib-bandbench-"))
        try:
            r = run(out, args.ranks, sets, args.petsc, args.timeout)
        finally:
            shutil.rmtree(out, ignore_errors=True)
        print(row(name, r, ref_lam), flush=True)
        phase_rows.append(phase_row(name, r))
        if args.json and "error" not in r:
            with open(args.json, "a") as fj:
                fj.write(json.dumps({"name": name, "ranks": args.ranks, "wall": r["wall"],
                                     "n_modes": len(r["lam"]), "stats": r["stats"],
                                     "eigenvalues": r["lam"].tolist()},
                                    default=float) + "\n")
        if "error" not in r:
            if ref_lam is None:
                ref_lam = r["lam"]
                ref_counts = len(ref_lam)
            print(f"<!-- {name}: progress lines {r['progress_lines']}, last: "
                  f"{r['last_progress']} -->", flush=True)
            for b in r["stats"].get("bands", []):
                st = b["stats"]
                print(f"<!--   band {b['index']} [{b['lo_hz']:.2f}, {b['hi_hz']:.2f}] shift "
                      f"{b['shift_hz']:.2f}: {b['n_modes']} modes, N(shift) {b['n_below']}, "
                      f"factor {st.get('time_factorization', 0):.1f} s "
                      f"({st.get('factor_memory_gb', 0):.2f} GB"
                      f"{', out of core' if st.get('out_of_core') else ''}), "
                      f"{st.get('linear_solves', 0)} RHS in "
                      f"{st.get('time_block_solves', 0):.1f} s, "
                      f"orth {st.get('time_orthogonalization', 0):.1f} s, band "
                      f"{st.get('time_band', 0):.1f} s; memory: before "
                      f"{st.get('rss_before_gb', float('nan')):.2f} GB, own peak "
                      f"{st.get('peak_rss_band_gb', float('nan')):.2f} GB, predicted "
                      f"{st.get('predicted_peak_gb', 0):.2f} GB, after freeing "
                      f"{st.get('rss_after_free_gb', float('nan')):.2f} GB, peak so far "
                      f"{st.get('peak_rss_gb', 0):.2f} GB -->", flush=True)
    print("\n| run | eigensolve [s] | " + " | ".join(h for h, _ in PHASES) +
          " | RR tests | purification + RR + checks | of which purification solves [s] | "
          "after Lanczos [s] (share) | longest silence [s] | load (1 min, before / after) |")
    print("|---" * (len(PHASES) + 8) + "|")
    for line in phase_rows:
        print(line, flush=True)
    if "eigsh" in args.reference:
        if ref_lam is None:
            print("| scipy eigsh | not run: no PETSc run gave the mode count |")
            return
        print(f"| scipy eigsh | {eigsh_row(args.refinement, ref_lam, args.timeout)}", flush=True)


def eigsh_row(refinement: float, ref_lam: np.ndarray, timeout: float) -> str:
    """The table row of scipy's ``eigsh`` for ``len(ref_lam)`` modes of the same case."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from modal_bench import run_scipy

    r = run_scipy(repr(refinement), len(ref_lam), timeout)
    if "error" in r:
        return f"failed: {r['error'].strip().splitlines()[-1]} |"
    lam = np.asarray(r["eigenvalues"])
    diff = np.abs(lam / ref_lam - 1).max()
    f = np.sqrt(lam) / (2 * np.pi)
    return (f"serial | {len(lam)} ({f[0]:.3f}-{f[-1]:.3f} Hz) | 1 | {r['wall']:.1f} | "
            f"{r['eigsh']:.1f} | (SuperLU, in eigsh) | | | | | | {r['peak_rss_gb']:.2f} | | "
            f"{diff:.1e} |")


if __name__ == "__main__":
    main()
