"""Rank-0 logging: stage messages, progress with ETA, and a timing table."""

from __future__ import annotations

import math
import sys
import time
from contextlib import contextmanager


class Reporter:
    """Prints on rank 0 only and collects stage timings.

    Parameters
    ----------
    rank
        MPI rank of this process; only rank 0 prints.
    stream
        Output stream (stdout by default).
    """

    def __init__(self, rank: int = 0, stream=None):
        self.rank = rank
        self.stream = stream or sys.stdout
        self.timings: list[tuple[str, float]] = []

    def info(self, msg: str) -> None:
        if self.rank == 0:
            print(msg, file=self.stream, flush=True)

    @contextmanager
    def stage(self, name: str):
        """Time a stage (also a PETSc log stage when petsc4py is already loaded)."""
        self.info(f"[{name}] ...")
        petsc_stage = None
        if "petsc4py.PETSc" in sys.modules:
            petsc_stage = sys.modules["petsc4py.PETSc"].Log.Stage(name)
            petsc_stage.push()
        t0 = time.perf_counter()
        failed = True
        try:
            yield
            failed = False
        finally:
            if petsc_stage is not None:
                petsc_stage.pop()
            dt = time.perf_counter() - t0
            self.timings.append((name, dt))
            self.info(f"[{name}] {'failed after' if failed else 'done in'} {dt:.2f} s")

    def progress(self, label: str, done: int, total: int, t_start: float) -> None:
        """One progress line: percent and ETA (``ETA --`` until something is done: no rate
        to extrapolate yet)."""
        if self.rank != 0 or total <= 0:
            return
        frac = done / total
        elapsed = time.perf_counter() - t_start
        eta = (f"{elapsed * (1 - frac) / frac:6.1f} s" if frac > 0 and math.isfinite(elapsed)
               else "    --")
        print(f"  {label}: {100 * frac:5.1f} %  elapsed {elapsed:6.1f} s  ETA {eta}",
              file=self.stream, flush=True)

    def timing_table(self) -> str:
        total = sum(t for _, t in self.timings)
        width = max([len(n) for n, _ in self.timings] + [5])
        lines = [f"{'stage':<{width}}  {'time [s]':>9}  {'share':>6}"]
        lines += [f"{n:<{width}}  {t:9.2f}  {100 * t / total if total else 0:5.1f}%"
                  for n, t in self.timings]
        lines.append(f"{'total':<{width}}  {total:9.2f}")
        return "\n".join(lines)
