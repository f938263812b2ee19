"""Record (or compare) what a coarse ``railvib run`` and ``railvib transient`` produce.

Issue 27 restructures the stages without changing any result. This tool records, for the
coarse thesis model on the current number of ranks, what a user sees of a run:

* per product file: its provenance (format version, stage, inputs digest, upstream files);
* per probe: the peak velocity and acceleration magnitudes;
* the reuse behaviour: which files a rerun reuses or recomputes, and which a rerun after
  one changed key (``output.dt``, which only the fields and probes depend on) recomputes.

Usage::

    mpirun -n 2 python tools/golden_run.py --write tests/data/golden_run.json   # record
    python tools/golden_run.py --compare tests/data/golden_run.json             # compare

``tests/test_golden_run.py`` runs the comparison on 1 and 2 ranks.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import re
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The coarse model of tests/test_pipeline.py (refinement 0.5, 12 modes).
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=12",
          "--set", "mbs.static_correction=true", "--set", "output.dt=0.004"]
#: The tiny direct run of tests/transient/transient_cases.py (TINY).
TRANSIENT = [a for s in ("mesh.refinement=0.25", "vehicle.x_start=2.7", "vehicle.x_end=4.2",
                         "output.dt=0.002", "output.stress_times=[0.04]",
                         "transient.checkpoint_interval=0", "transient.f_max=100")
             for a in ("--set", s)]
#: The one key changed for the third run: only the fields, probes and assessment use it.
CHANGED = ["--set", "output.dt=0.008"]
#: Lines of the stages' reuse verdicts ("reusing <path> (why)", "recomputing <path>:
#: why"): the verb and what follows up to the reason, the output folder written <out>.
VERDICT = re.compile(r"\b((?:reusing|recomputing)\s[^(:\n]*)")
#: Relative agreement of the probe peaks. Run to run on one machine the results are bit
#: for bit the same; across machines and rank counts the eigensolver converges to
#: modal.tol = 1e-8 (relative residual), which moves the peaks by far less than this.
PEAK_RTOL = 1e-6


def _cli(argv: list[str]) -> tuple[int, str]:
    """Run the CLI in this process; its exit code and what rank 0 printed."""
    from railvib_hpc.cli import run

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = run(argv)
    return code, buf.getvalue()


def _verdicts(text: str, out: Path) -> list[str]:
    text = text.replace(str(out), "<out>")
    return sorted({m.group(1).strip() for m in VERDICT.finditer(text)})


def _provenance(out: Path) -> dict[str, dict]:
    from railvib_hpc.io.products import STAGE_FILES
    from railvib_hpc.io.provenance import read_provenance

    rows = {}
    for spec in STAGE_FILES.values():
        path = out / spec.filename
        if not path.exists():
            continue
        prov = read_provenance(path)
        if prov.get("railvib_file") != spec.name:
            continue
        rows[spec.name] = {"format_version": int(prov["format_version"]),
                           "stage": prov["stage"], "inputs_sha256": prov["inputs_sha256"],
                           "upstream": sorted(json.loads(prov["upstream_sha256"]))}
    return rows


def _peaks(out: Path) -> dict[str, list[float]]:
    with h5py.File(out / "probes.h5", "r") as f:
        return {str(g.attrs["name"]): [
            float(np.linalg.norm(g[k][()], axis=-1).max()) for k in ("velocity", "acceleration")]
            for g in f["probes"].values()}


def _check_on_root(check: Callable[[Path, str, str], None], run_dir: Path, texts: list[str],
                   comm: MPI.Comm) -> None:
    """``check`` on rank 0; a failure there is raised on every rank (none is left waiting in
    the next run's collectives)."""
    failure = None
    if comm.rank == 0:
        try:
            check(run_dir, *texts)
        except AssertionError as exc:
            failure = exc
    if comm.bcast(failure is not None):
        raise failure or AssertionError("the end-to-end checks failed on rank 0")


def record(folder: Path, check: Callable[[Path, str, str], None] | None = None) -> dict:
    """Run the coarse ``run`` three times and the coarse ``transient`` twice in ``folder``.

    ``check(run_folder, first_output, rerun_output)``, when given, is called on rank 0
    after the second ``run`` (which reuses everything), before the third changes a key:
    the end-to-end checks of the outputs share the runs the record needs.
    """
    comm = MPI.COMM_WORLD
    out = {}
    run_dir, tr_dir = folder / "run", folder / "transient"
    texts = []
    for extra in ([], [], CHANGED):
        code, text = _cli(["run", str(BASELINE), *COARSE, *extra, "--out", str(run_dir)])
        if code:
            raise SystemExit(f"railvib run exited with {code}")
        texts.append(text)
        if not extra and len(texts) == 1:
            out["run"] = {"provenance": _provenance(run_dir) if comm.rank == 0 else {},
                          "peaks": _peaks(run_dir) if comm.rank == 0 else {}}
        if len(texts) == 2 and check is not None:
            _check_on_root(check, run_dir, texts, comm)
    out["run"]["rerun"] = _verdicts(texts[1], run_dir)
    out["run"]["changed"] = _verdicts(texts[2], run_dir)
    texts = []
    for _ in range(2):
        code, text = _cli(["transient", str(BASELINE), *TRANSIENT, "--out", str(tr_dir)])
        if code:
            raise SystemExit(f"railvib transient exited with {code}")
        texts.append(text)
    out["transient"] = {"provenance": _provenance(tr_dir) if comm.rank == 0 else {},
                        "peaks": _peaks(tr_dir) if comm.rank == 0 else {},
                        "rerun": _verdicts(texts[1], tr_dir)}
    return out


def differences(expected: dict, got: dict) -> list[str]:
    """What differs between two records of the same rank count."""
    bad = []
    for cmd in ("run", "transient"):
        e, g = expected[cmd], got[cmd]
        if e["provenance"] != g["provenance"]:
            for name in sorted(set(e["provenance"]) | set(g["provenance"])):
                if e["provenance"].get(name) != g["provenance"].get(name):
                    bad.append(f"{cmd}: provenance of {name}: {e['provenance'].get(name)} != "
                               f"{g['provenance'].get(name)}")
        if set(e["peaks"]) != set(g["peaks"]):
            bad.append(f"{cmd}: probes {sorted(e['peaks'])} != {sorted(g['peaks'])}")
        for probe in sorted(set(e["peaks"]) & set(g["peaks"])):
            if not np.allclose(g["peaks"][probe], e["peaks"][probe], rtol=PEAK_RTOL, atol=0):
                bad.append(f"{cmd}: peaks of {probe}: {g['peaks'][probe]} != "
                           f"{e['peaks'][probe]} (rtol {PEAK_RTOL:g})")
        for key in ("rerun", "changed"):
            if key in e and e[key] != g[key]:
                bad.append(f"{cmd}: {key} verdicts {g[key]} != {e[key]}")
    return bad


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--write", type=Path, help="record into this JSON (key: rank count)")
    p.add_argument("--compare", type=Path, help="compare with this JSON")
    args = p.parse_args(argv)
    comm = MPI.COMM_WORLD
    folder = Path(tempfile.mkdtemp(prefix="golden-")) if comm.rank == 0 else None
    folder = Path(comm.bcast(str(folder) if folder else None))
    got = record(folder)
    if comm.rank:
        return 0
    key = str(comm.size)
    if args.write:
        doc = json.loads(args.write.read_text()) if args.write.exists() else {}
        doc[key] = got
        args.write.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
        print(f"recorded {key} rank(s) in {args.write}")
    if args.compare:
        bad = differences(json.loads(args.compare.read_text())[key], got)
        print("\n".join(bad) or f"identical to {args.compare} ({key} rank(s))")
        return 1 if bad else 0
    return 0


if __name__ == "__main__":
    sys.exit(main())
