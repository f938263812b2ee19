"""Helpers of the fault-injection suite: the CLI in a subprocess with a time limit, copies
of result folders, tmpfs mounts and the tally of outcomes (see conftest.py)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The coarse model of the issue's measurements.
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=20",
          "--set", "output.dt=0.01"]
#: Files of a finished run (the reports are left out of the copies: big, not read).
RESULT_FILES = ("mesh.h5", "mesh.msh", "mesh.xdmf", "mesh_report.json", "modes.h5",
                "modes.xdmf", "mbs.h5", "fields.h5", "fields.xdmf", "stress.xdmf", "probes.h5",
                "assessment.json")
ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
           PYTHONUNBUFFERED="1")
serial_only = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                 reason="spawns its own processes; runs in the serial pass")


@dataclass
class Result:
    """Outcome of a CLI subprocess."""

    code: int | None
    out: str
    err: str
    seconds: float
    timed_out: bool

    @property
    def error_lines(self) -> list[str]:
        return [ln for ln in self.err.splitlines() if ln.startswith("railvib ")
                and ": error: " in ln]

    @property
    def outcome(self) -> str:
        """``hang``, ``traceback``, ``clear error`` (exit 2, or 3 for a diverged run, with one
        error line), ``internal error``, ``ok`` or ``unclear``."""
        if self.timed_out:
            return "hang"
        if "Traceback" in self.err or "Traceback" in self.out:
            return "traceback"
        if self.code == 2 and len(self.error_lines) == 1:
            return "clear error"
        if self.code == 3 and len(self.error_lines) == 1 and "diverged" in self.err:
            return "clear error"       # a diverged time integration, stopped in one line
        if self.code == 1 and "please report" in self.err:
            return "internal error"
        if self.code == 0:
            return "ok"
        return "unclear"


def cli(args: list[str], *, ranks: int = 1, timeout: float = 300, cwd: Path | None = None,
        preexec=None) -> Result:
    """Run ``railvib ARGS`` (under ``mpirun -n ranks`` when ranks > 1) with a time limit."""
    cmd = [sys.executable, "-m", "railvib_hpc", *map(str, args)]
    if ranks > 1:
        cmd = [shutil.which("mpirun") or "mpirun", "--oversubscribe", "-n", str(ranks), *cmd]
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, cwd=cwd,
                           env=ENV, preexec_fn=preexec)
        return Result(p.returncode, p.stdout, p.stderr, time.perf_counter() - t0, False)
    except subprocess.TimeoutExpired as exc:
        out = exc.stdout.decode() if isinstance(exc.stdout, bytes) else (exc.stdout or "")
        err = exc.stderr.decode() if isinstance(exc.stderr, bytes) else (exc.stderr or "")
        return Result(None, out, err, time.perf_counter() - t0, True)


class Tally:
    """Outcomes of the injected faults (one entry per try)."""

    def __init__(self):
        self.entries: list[dict] = []

    def add(self, fault: str, outcome: str, detail: str = "") -> str:
        self.entries.append({"fault": fault, "outcome": outcome, "detail": detail[:300]})
        return outcome

    def result(self, fault: str, res: Result, expect: str = "clear error") -> Result:
        """Record a CLI outcome (``silent wrong`` when it exits 0 where a refusal was due)."""
        outcome = res.outcome
        if expect == "clear error" and outcome == "ok":
            outcome = "silent wrong"
        detail = (res.error_lines or [res.err.strip().splitlines()[-1] if res.err.strip()
                                      else ""])[0]
        self.add(fault, outcome, detail)
        return res

    def counts(self) -> dict:
        return tally_counts(self.entries)


#: The outcomes the summary always names, in its order.
OUTCOMES = ("clear error", "recomputed", "warning", "traceback", "hang", "silent wrong")


def tally_counts(entries: list[dict]) -> dict:
    """``{"tries": n, outcome: count, ...}`` of the entries of :class:`Tally` (every
    outcome of :data:`OUTCOMES` present, 0 where none)."""
    out = {"tries": len(entries)}
    for e in entries:
        out[e["outcome"]] = out.get(e["outcome"], 0) + 1
    for k in OUTCOMES:
        out.setdefault(k, 0)
    return out


def write_tally(entries: list[dict]) -> None:
    """``RAILVIB_FAULT_TALLY=<file>``: the counts and entries as JSON there."""
    path = os.environ.get("RAILVIB_FAULT_TALLY")
    if path:
        import json

        Path(path).write_text(json.dumps({"counts": tally_counts(entries), "entries": entries},
                                         indent=1))


def tally_line(entries: list[dict]) -> str:
    """The terminal summary's line of the fault-injection suite."""
    c = tally_counts(entries)
    return (f"fault-injection suite: {c['tries']} tries, {c['clear error']} clear errors, "
            f"{c['recomputed']} recomputed, {c['warning']} warnings, {c['traceback']} "
            f"tracebacks, {c['hang']} hangs, {c['silent wrong']} silent wrong results"
            + "".join(f", {v} {k}" for k, v in c.items() if k not in ("tries", *OUTCOMES)))


TALLY = Tally()


def copy_results(src: Path, dst: Path, names=RESULT_FILES) -> Path:
    """Copy result files with their records (``.railvib/<name>.json``), keeping mtimes."""
    (dst / ".railvib").mkdir(parents=True, exist_ok=True)
    for name in names:
        if (src / name).exists():
            shutil.copy2(src / name, dst / name)
            rec = src / ".railvib" / f"{name}.json"
            if rec.exists():
                shutil.copy2(rec, dst / ".railvib" / rec.name)
    if "probes.h5" in names and (src / "probes").is_dir() and not (dst / "probes").exists():
        shutil.copytree(src / "probes", dst / "probes")
    return dst


def can_mount() -> bool:
    """True when this process may mount a tmpfs (root in a container that allows it)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        return False
    d = tempfile.mkdtemp(prefix="railvib-mnt-")
    try:
        ok = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", d],
                            capture_output=True).returncode == 0
        if ok:
            subprocess.run(["umount", d], capture_output=True)
        return ok
    finally:
        os.rmdir(d)
