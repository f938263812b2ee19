"""The registry of the stages, the pipelines of stages, and the loop that runs them.

:data:`STAGES` is the registry: every stage's name and the module that declares it (its
``STAGE``, a :class:`~railvib_hpc.io.stage_protocol.Stage`), in pipeline order. Adding a
stage is one module with its ``STAGE`` (its products' rows, checks and case keys
included) and one line here (or :func:`register`). The
command line takes its stage commands and their help lines from it, the Python API
(:class:`~railvib_hpc.api.Pipeline`) and the studies run every stage through it, and
:data:`PIPELINES` names the commands that run several stages in order: ``railvib run``
(the modal solution) and ``railvib transient`` (the full-order solution, then its
assessment).

Every call goes through one :class:`~railvib_hpc.io.stage_protocol.StageRunner`: the
output folder's lock (once per command), the PETSc options' scope, ``run.json`` and the
timings; :func:`run_stages` is the loop over a sequence.

The graph of the stages is the registry's too: each stage names the stages whose products
it reads (:attr:`~railvib_hpc.io.stage_protocol.Stage.needs`; :func:`stage_graph`
checks that they are registered and form no cycle), and the runner hands a stage those
products (:meth:`~railvib_hpc.io.stage_protocol.StageContext.input`), building the mesh
on demand and verifying the rest. What a command refuses is what its stages refuse
(:func:`refusals`, :func:`command_stages`), checked before anything runs.

Example
-------
>>> from railvib_hpc.pipeline import PIPELINES, stage, stage_graph
>>> PIPELINES["run"]
('mesh', 'modal', 'mbs', 'reconstruct', 'assess')
>>> PIPELINES["transient"]
('transient', 'assess')
>>> stage("modal").products
('modes.h5', 'static.h5', 'modal_damping.h5', 'bands/index.json')
>>> stage_graph()["reconstruct"]
('modal', 'mbs')
"""

from __future__ import annotations

import importlib
from collections.abc import Sequence

from .io.stage_protocol import Refusal, Stage, StageRun, StageRunner

#: The registry: stage name -> the module declaring its ``STAGE``, in pipeline order.
STAGES: dict[str, str] = {
    "mesh": "railvib_hpc.mesh.stage",
    "modal": "railvib_hpc.modal.stage",
    "mbs": "railvib_hpc.mbs.stage",
    "reconstruct": "railvib_hpc.reconstruct.stage",
    "transient": "railvib_hpc.transient.stage",
    "assess": "railvib_hpc.assess.stage",
}

#: Writers of products that are not stages: name -> the module declaring their rows (the
#: studies' ``result.json``).
PRODUCT_WRITERS: dict[str, str] = {"study": "railvib_hpc.studies.common"}

#: Commands that run a sequence of stages: name -> the stages, in order.
PIPELINES: dict[str, tuple[str, ...]] = {
    "run": ("mesh", "modal", "mbs", "reconstruct", "assess"),
    "transient": ("transient", "assess"),
}
#: The stages ``railvib run`` runs, in order.
PIPELINE_ORDER: tuple[str, ...] = PIPELINES["run"]
#: ``railvib transient``: the full-order solution, then its assessment.
TRANSIENT_PIPELINE: tuple[str, ...] = PIPELINES["transient"]


def register(name: str, module: str) -> None:
    """Add stage ``name``, declared by ``module`` (its ``STAGE``), to the registry."""
    STAGES[name] = module


def stage(name: str) -> Stage:
    """The declaration of stage ``name`` (its module imported on first use).

    Raises
    ------
    ValueError
        For a name that is not in the registry.
    """
    if name not in STAGES:
        raise ValueError(f"unknown stage {name!r}; stages: {', '.join(STAGES)}")
    declared = importlib.import_module(STAGES[name]).STAGE
    if declared.name != name:
        raise ValueError(f"{STAGES[name]} declares stage {declared.name!r}, not {name!r}")
    return declared


def declare_products() -> None:
    """Declare every product's row: import each registered stage's module (its ``STAGE``
    declares its products) and each of :data:`PRODUCT_WRITERS`, by name. The product
    table (:data:`~railvib_hpc.io.products.STAGE_FILES`) calls it when it is read whole or
    for a name it lacks."""
    for module in (*STAGES.values(), *PRODUCT_WRITERS.values()):
        importlib.import_module(module)


def stage_graph() -> dict[str, tuple[str, ...]]:
    """Every registered stage and the stages it needs, upstream first (a topological order).

    Raises
    ------
    ValueError
        For a need that is not a registered stage, or a cycle of needs.
    """
    needs = {name: stage(name).needs for name in STAGES}
    for name, wanted in needs.items():
        unknown = [n for n in wanted if n not in needs]
        if unknown:
            raise ValueError(f"stage {name} needs {unknown[0]!r}, which is not a stage; "
                             f"stages: {', '.join(STAGES)}")
    order: dict[str, tuple[str, ...]] = {}
    visiting: list[str] = []

    def visit(name: str) -> None:
        if name in order:
            return
        if name in visiting:
            cycle = visiting[visiting.index(name):] + [name]
            raise ValueError("the stages' needs form a cycle: " + " -> ".join(cycle))
        visiting.append(name)
        for upstream in needs[name]:
            visit(upstream)
        visiting.pop()
        order[name] = needs[name]

    for name in needs:
        visit(name)
    return order


def command_stages(command: str) -> tuple[str, ...]:
    """The stages a ``railvib`` command runs: a pipeline's (:data:`PIPELINES`), a stage's
    own, none for the others (``check``; ``study``, whose studies refuse what they cannot
    do themselves)."""
    if command in PIPELINES:
        return PIPELINES[command]
    return (command,) if command in STAGES else ()


def refusals(case, command: str) -> list[Refusal]:
    """What ``case`` asks of ``command`` that one of its stages cannot do: the first
    refusal, in the stages' order (one line), or nothing
    (:meth:`~railvib_hpc.io.stage_protocol.Stage.refusals`; the sentences name
    ``command``)."""
    for name in command_stages(command):
        found = stage(name).refusals(case, command)
        if found:
            return found[:1]
    return []


def single_stage_commands() -> dict[str, str]:
    """The stages that are commands of their own (not a pipeline's name): name -> help."""
    return {name: stage(name).help for name in STAGES if name not in PIPELINES}


def run_stage(runner: StageRunner, name: str, case, *, command: str | None = None,
              **options) -> StageRun:
    """Run the registered stage ``name`` through ``runner`` (see
    :meth:`~railvib_hpc.io.stage_protocol.StageRunner.run`)."""
    return runner.run(stage(name), case, command=command, **options)


def run_stages(runner: StageRunner, names: Sequence[str], case, *,
               command: str | None = None) -> dict[str, StageRun]:
    """Run the registered stages ``names`` in order in one session of ``runner`` (one lock
    of the folder, one scope of the PETSc options); each reuses what is current and is
    recorded in ``run.json``.

    Raises
    ------
    ValueError
        For a name that is not a stage (before anything runs).
    """
    stages = [stage(n) for n in names]
    with runner.session(command):
        return {s.name: runner.run(s, case, command=command) for s in stages}
