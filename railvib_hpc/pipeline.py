"""The stages in pipeline order, each with the same entry point.

Every stage is a function ``run_<stage>_stage(case, out_dir, comm, rep,
petsc_options=None) -> dict``: collective over ``comm``, self-contained (it starts
PETSc when it needs it, takes the lock of ``out_dir``, verifies its input files, reuses
or recomputes its outputs through :mod:`railvib_hpc.io.stage_files`) and returns a
summary dict on every rank. User and environment errors raise
:class:`~railvib_hpc.errors.UserError` on every rank.

:func:`call_stage` is how a stage is called from outside: it holds the output folder's
lock and records the call (wall time, peak memory of every rank, versions, the command
and the case digest) in ``<out>/run.json`` (:mod:`railvib_hpc.io.run_record`).
The CLI and the Python API (:mod:`railvib_hpc.api`) call every stage through it.
The full-order solution (``railvib transient``) is a stage with the same entry point
that ``run`` does not include (:data:`OPTIONAL_STAGES`); the ``transient`` command runs
:data:`TRANSIENT_PIPELINE`.

Example
-------
>>> from railvib_hpc.pipeline import STAGES, TRANSIENT_PIPELINE
>>> list(STAGES)
['mesh', 'modal', 'mbs', 'reconstruct', 'assess']
>>> TRANSIENT_PIPELINE
('transient', 'assess')
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

#: Stage name -> (module, entry point), in pipeline order.
STAGES: dict[str, tuple[str, str]] = {
    "mesh": ("railvib_hpc.mesh.stage", "run_mesh_stage"),
    "modal": ("railvib_hpc.modal.stage", "run_modal_stage"),
    "mbs": ("railvib_hpc.mbs.stage", "run_mbs_stage"),
    "reconstruct": ("railvib_hpc.reconstruct.stage", "run_reconstruct_stage"),
    "assess": ("railvib_hpc.assess.stage", "run_assess_stage"),
}

#: The stages ``railvib run`` (and :func:`run_pipeline`) runs, in order.
PIPELINE_ORDER: tuple[str, ...] = ("mesh", "modal", "mbs", "reconstruct", "assess")
#: Stages with the same entry point that ``railvib run`` does not run.
OPTIONAL_STAGES: dict[str, tuple[str, str]] = {
    "transient": ("railvib_hpc.transient.stage", "run_transient_stage"),
}
#: ``railvib transient``: the full-order solution, then its assessment.
TRANSIENT_PIPELINE = ("transient", "assess")

StageRunner = Callable[..., dict]


def stage_runner(name: str) -> StageRunner:
    """The entry point of stage ``name`` (imported on first use)."""
    module, func = STAGES[name] if name in STAGES else OPTIONAL_STAGES[name]
    return getattr(importlib.import_module(module), func)


def call_stage(name: str, case, out_dir: str | Path, comm, rep,
               petsc_options: list[str] | None = None, *, command: str | None = None,
               wait: bool = False) -> dict:
    """Run stage ``name`` under the lock of ``out_dir`` and record it in ``run.json``.

    Parameters
    ----------
    name
        A key of :data:`STAGES`.
    case, out_dir, comm, rep, petsc_options
        As for every stage entry point.
    command
        What ran it, for ``run.json`` (default ``railvib <name>``).
    wait
        Wait for another command holding the folder instead of refusing.

    Returns
    -------
    dict
        The stage's summary (every rank).
    """
    from .io.run_record import record_stage
    from .io.stage_files import output_lock

    out_dir = Path(out_dir)
    command = command or f"railvib {name}"
    with output_lock(out_dir, comm, command, wait=wait, rep=rep), \
            record_stage(out_dir, comm, name, case, rep, command) as call:
        summary = stage_runner(name)(case, out_dir, comm, rep, petsc_options)
        call.done(summary)
    return summary


def run_pipeline(case, out_dir: str | Path, comm, rep, petsc_options: list[str] | None = None,
                 stages: tuple[str, ...] | None = None, *, command: str | None = None,
                 wait: bool = False) -> dict[str, dict]:
    """Run the stages in order (all by default) under one lock of ``out_dir``.

    Each stage reuses what is current and recomputes what is stale or corrupt, saying
    why; each call is recorded in ``run.json`` (:func:`call_stage`). Returns
    ``{stage: summary}``.
    """
    from .io.stage_files import output_lock

    out_dir = Path(out_dir)
    command = command or "railvib run"
    summaries = {}
    with output_lock(out_dir, comm, command, wait=wait, rep=rep):
        for name in stages or PIPELINE_ORDER:
            summaries[name] = call_stage(name, case, out_dir, comm, rep, petsc_options,
                                         command=command)
    return summaries
