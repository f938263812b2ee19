"""The stages in pipeline order, each with the same entry point.

Every stage is a function ``run_<stage>_stage(case, out_dir, comm, rep,
petsc_options=None) -> dict``: collective over ``comm``, self-contained (it starts
PETSc when it needs it, takes the lock of ``out_dir``, verifies its input files, reuses
or recomputes its outputs through :mod:`railvib_hpc.io.stage_files`) and returns a
summary dict on every rank. User and environment errors raise
:class:`~railvib_hpc.errors.UserError` on every rank.

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


def run_pipeline(case, out_dir: str | Path, comm, rep, petsc_options: list[str] | None = None,
                 stages: tuple[str, ...] | None = None) -> dict[str, dict]:
    """Run the stages in order (all by default) under one lock of ``out_dir``.

    Each stage reuses what is current and recomputes what is stale or corrupt, saying
    why. Returns ``{stage: summary}``.
    """
    from .io.stage_files import output_lock

    out_dir = Path(out_dir)
    summaries = {}
    with output_lock(out_dir, comm, "railvib run", rep=rep):
        for name in stages or tuple(STAGES):
            summaries[name] = stage_runner(name)(case, out_dir, comm, rep, petsc_options)
    return summaries
