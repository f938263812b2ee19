"""Small full-order cases for the transient tests (coarse thesis model, short runs)."""

from __future__ import annotations

from pathlib import Path

from railvib_hpc.config import load_case

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"

#: Coarse thesis model, the wheelset entering the flexible rail at 10 ms and 50 ms later
#: at x_end; output every 2 ms, stresses at 40 ms, no wall-clock checkpoints.
TINY = ["mesh.refinement=0.25", "vehicle.x_start=2.7", "vehicle.x_end=4.2",
        "output.dt=0.002", "output.stress_times=[0.04]", "transient.checkpoint_interval=0",
        "transient.f_max=100"]


def tiny_case(*extra: str):
    """The tiny case with extra overrides."""
    return load_case(BASELINE, [*TINY, *extra])


def run_transient_only(out, overrides, comm=None) -> None:
    """``railvib transient``'s integration of the baseline with ``overrides`` (``key=value``)
    into ``out``, without the assessment (for the tests that compare probes.h5 or
    transient.h5 only: the assessment's report costs ~10 s a run)."""
    from mpi4py import MPI

    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    comm = comm or MPI.COMM_WORLD
    run_transient_stage(load_case(BASELINE, list(overrides)), out, comm, Reporter(comm.rank))
