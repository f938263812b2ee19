"""The ``transient`` stage: direct time integration of the full finite-element model.

``railvib transient CASE`` (collective) builds the same model as the modal stage (mesh,
DOFs with the ``[boundary]`` conditions, K and M), adds the damping matrix C of
``[damping]`` and the absorbing faces' dashpots, and integrates ``M u'' + C u' + K u = f``
with the engine of ``transient.engine`` (:mod:`.engine`, declared in
:data:`railvib_hpc.time_engines.ENGINES`; ``direct``: the generalized-alpha scheme,
:mod:`.scheme`, on one MUMPS factor of the effective matrix). The run is set up as one
typed object (:func:`~.run_setup.setup_run`), which the loop steps, records and
checkpoints (:class:`TimeLoop`). The loads are the
moving forces or the vehicle of ``[vehicle]`` with the Hertz contact and the
irregularities of ``[irregularity]``, exactly as in the ``mbs`` stage (same vehicle models
and contact solver, :mod:`.integrate`), but on the full model: a causal solution whose
waves travel at the speeds of the mesh, with no truncation of a modal basis. A site
without a track (``track.count = 0``) is loaded instead by the point loads of ``[load]``
moving over its bare ground (:mod:`.surface_case`): no rail, wheel or vehicle, so the
rail and wheel tables below are empty and ``probes.h5`` has no ``/rail``.

Outputs in the output folder (the layout of ``reconstruct``'s files, so ``assess`` and the
studies read them unchanged; their own rows of
:data:`railvib_hpc.io.products.STAGE_FILES`):

* ``fields.h5`` + ``fields.xdmf`` (+ ``fields_views.h5``): every node at the steps of
  ``output.dt`` within ``output.window``; ``/stress`` + ``stress.xdmf`` (+
  ``stress_views.h5``) at ``output.stress_times``;
* ``probes.h5`` + ``probes/<name>.csv``: the mesh probes and ``output.probes`` (with their
  roles) at every step, and ``/rail`` with the rail bending moments (full model: nothing
  left out);
* ``transient.h5``: ``/time``; ``/wheels/x, contact_force, penetration,
  rail_displacement, wheel_height, rail_index``; ``/vehicle/y, y_dot, y_ddot``;
  ``/rail/x, uz, ry``; attribute ``stats`` (run statistics, contact forces).

Every file carries its provenance and is written checked, atomically and recorded
(:mod:`railvib_hpc.io.atomic`); the mesh is ``mesh.h5`` of the same folder, which the
stage needs (``Stage(needs=("mesh",))``): the runner hands it over built or reused as by
``railvib mesh`` (``ctx.input("mesh")``).

Size: before the mesh is built, the number of steps and the memory of the histories are
checked (:func:`precheck_size`, :data:`MAX_TRANSIENT_STEPS`); a run that would exceed them
is refused in one line (exit 2), and again with the exact step once the mesh is known.

Reuse: a rerun reuses the three products when all are current and sound for the case
(:func:`previous_results`); otherwise it says why in one line (``recomputing the transient
results in OUT: transient.h5 was computed with vehicle.speed = 30, the case says 20``) and
recomputes all three (they come from one time integration). Changed
``output.stress_times`` alone only recompute ``/stress`` of the reused ``fields.h5``.

Checkpoints: an interrupted run resumes from its last checkpoint
(``transient_checkpoint.h5``, every ``transient.checkpoint_interval`` seconds) and gives
the same answer, bit for bit on one rank: the state is stored exactly, the factor is
recomputed deterministically and the rail columns are computed in fixed blocks
(:class:`~.integrate.RailColumns`). The engine's own state is in it too
(:meth:`~.engine.Engine.state`: the perfectly matched layers' memory, by global DOF and
element, so that a run with layers resumes on any number of ranks). On several ranks
MUMPS's parallel factorization is
reproducible only to its round-off (two uninterrupted 2-rank runs differ by ~4e-9
relative), and a resumed run lies within that spread (docs/transient.md).
The checkpoint is a stage file too: it is resumed only when it is current for the case,
computed from the same ``mesh.h5``, unchanged and sound, and when the partial
``fields.h5`` (``.fields.h5.resume``) carries its run id; otherwise the run starts at
t = 0 and says why.
"""

from __future__ import annotations

import contextlib
import json
import math
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config import Case
from ..errors import ContactNewtonError, DivergenceError
from ..io.atomic import ensure_space
from ..io.digests import digest, record_file
from ..io.files import (
    FIELDS_H5,
    FIELDS_XDMF,
    MESH_H5,
    PROBES_CSV_DIR,
    PROBES_H5,
    STRESS_XDMF,
    TRANSIENT_CHECKPOINT_H5,
    TRANSIENT_FIELDS,
    TRANSIENT_H5,
    TRANSIENT_PROBES,
)
from ..io.formats.fields import check_fields
from ..io.formats.probes import check_probes
from ..io.formats.transient import (
    CheckpointHeader,
    check_checkpoint,
    check_transient,
    read_checkpoint,
    transient_stats,
    write_checkpoint,
    write_transient_h5,
)
from ..io.products import Selection, StageFile, inputs_hash
from ..io.stage_protocol import NotReusable, Stage, StageContext, StageOutput, StageRunner
from ..io.temp_names import resume_path
from ..io.xdmf import remove_xdmf
from ..log import Reporter
from ..parallel import on_root
from ..problem import RANDOM_FIELD_KEYS, Problem
from ..resources import peak_memory_gb
from ..site import line_probes
from .engine import gather_state
from .engines import TransientInputError, initial_state  # noqa: F401 (re-exported)
from .integrate import State, StepInfo
from .output import FieldWriter
from .run_setup import (  # noqa: F401 (re-exported: the setup's parts, for scripts, tests)
    HISTORY_COPIES,
    MAX_TRANSIENT_STEPS,
    NEAR_CRITICAL_SPEED,
    TransientRun,
    band_check,
    check_run_size,
    check_stress_times,
    history_bytes,
    output_steps,
    precheck_size,
    probe_points,
    setup_run,
    speed_warning,
    time_step,
)
from .run_setup import setup_run as _setup  # noqa: F401 (the name scripts use)
from .spectral_refusals import spectral_refusals
from .surface_case import uses_surface_load

#: Table names of the products (:data:`railvib_hpc.io.products.STAGE_FILES`), in the
#: order they are checked (the solution first; it is written last).
FIELDS, PROBES, HISTORIES = TRANSIENT_FIELDS, TRANSIENT_PROBES, TRANSIENT_H5
PRODUCTS = (HISTORIES, FIELDS, PROBES)
CHECKPOINT = TRANSIENT_CHECKPOINT_H5
#: Output steps buffered per collective write of fields.h5.
FIELD_BLOCK = 16


class Interrupted(RuntimeError):
    """Raised by the ``stop_after`` test hook after a checkpoint (simulates a killed run)."""


# --------------------------------------------------------------------------- reuse
def _checks_context(case: Case, out_dir: Path | None = None) -> dict:
    """What the data check of ``transient.h5`` needs: the static wheel load (also as the
    row's ``check_context``, for a stage that verifies it)."""
    from ..mbs.case_vehicle import static_wheel_load

    return {"static_wheel_load": static_wheel_load(case)}


def previous_results(ctx: StageContext) -> dict | None:
    """The run statistics of current, sound transient results in the folder (rank 0).

    ``fields.h5``, ``probes.h5`` and ``transient.h5`` must all pass
    :func:`~railvib_hpc.io.provenance.examine` for the case (with their data checks and
    companions). Otherwise the reason is printed in one line (unless there is nothing
    at all), the three are deleted, and None is returned
    (:meth:`~railvib_hpc.io.stage_protocol.StageContext.reuse_together`).
    """
    verdicts = ctx.reuse_together(PRODUCTS, "transient results",
                                  context=_checks_context(ctx.case))
    if verdicts is None:
        return None
    return transient_stats(verdicts[HISTORIES].attrs)


def stress_key(case: Case) -> str:
    """Inputs hash of ``/stress`` in ``fields.h5``: the fields' and the stress times."""
    return digest({"fields": inputs_hash(case, FIELDS),
                   "times": [float(t) for t in case["output.stress_times"]]})


def _stress_current(out_dir: Path, key: str) -> bool:
    from ..io.formats.fields import FieldsFile

    try:
        ok = FieldsFile(out_dir / FIELDS_H5).stress_current(key)
    except (OSError, KeyError):
        return False
    return ok and (out_dir / STRESS_XDMF).is_file()


def _refresh_stress(case: Case, out_dir: Path, comm, rep: Reporter) -> None:
    """``/stress`` of reused fields: kept when current, else recomputed in place."""
    if not case["output.stress_times"]:
        return
    fields = out_dir / FIELDS_H5
    key = on_root(lambda: stress_key(case), comm)
    if on_root(lambda: _stress_current(out_dir, key), comm):
        rep.info(f"reusing /stress of {fields}")
        return

    def check_times() -> int:
        from ..io.formats.fields import FieldsFile

        stored = FieldsFile(fields)
        check_stress_times(case, stored.times())
        n_hexes = stored.n_hexes()
        ensure_space(out_dir, _stress_bytes(case, n_hexes), "the stresses of fields.h5")
        return n_hexes

    with rep.stage("transient: stresses"):
        on_root(check_times, comm)
        _stress_writer(case, comm, rep, key)(fields)    # rewritten in place: record again
        record_file(fields, comm)


def _stress_bytes(case: Case, n_hexes: int) -> int:
    n = len(case["output.stress_times"])
    return 16 * n * int(n_hexes) + 16 * n


def _resumable(ctx: StageContext, mesh_sha: str, n_fields: tuple, nt: int,
               engine_state: bool = False) -> str | None:
    """The run id of a checkpoint this run may resume, or None (rank 0).

    The checkpoint must be current for the case and computed from this ``mesh.h5``,
    unchanged and sound (:func:`~railvib_hpc.io.provenance.examine`), hold the engine's
    own state when it has one (``engine_state``: the layers' memory), and the partial
    ``fields.h5`` must carry the fields' provenance and the checkpoint's run id. Anything
    else is deleted, saying why.
    """
    import h5py

    partial = resume_path(ctx.out_dir / FIELDS_H5)

    def matching(v) -> str:
        header = CheckpointHeader.of_attrs(v.attrs)
        run_id, step, written = header.run_id, header.step, header.fields_written
        try:
            with h5py.File(partial, "r") as f:
                a = f.attrs
                if (a.get("railvib_file") != FIELDS or a.get("inputs_sha256")
                        != inputs_hash(ctx.case, FIELDS) or a.get("run_id") != run_id):
                    raise NotReusable(f"the partial fields file {partial.name} belongs to "
                                      "another run")
                if f["fields/displacement"].shape != n_fields:
                    raise NotReusable(f"the partial fields file {partial.name} has another "
                                      "shape")
        except (OSError, KeyError):
            raise NotReusable(f"its partial fields file {partial.name} is missing or "
                              "unreadable") from None
        if not (0 <= step < nt and 0 <= written <= n_fields[0]):
            raise NotReusable(f"it is at step {step} of {nt} with {written} output steps "
                              "written")
        if engine_state:
            with h5py.File(ctx.out_dir / CHECKPOINT, "r") as f:
                if "engine" not in f:
                    raise NotReusable("it has no engine state (the perfectly matched "
                                      "layers' memory)")
        return run_id

    old = ctx.reuse(CHECKPOINT, accept=matching, upstream={MESH_H5: mesh_sha},
                    stale=lambda ckpt, why: f"not resuming from {ckpt}: {why}; starting at "
                                            "t = 0")
    if old.ok:
        return old.value
    partial.unlink(missing_ok=True)
    return None


# --------------------------------------------------------------------------- setup
class Recorder:
    """Rank 0's histories of the run (every step)."""

    def __init__(self, nt: int, n_wheels: int, n_dof: int, n_probes: int, rail_shape):
        self.arrays = {
            "contact_force": np.zeros((nt + 1, n_wheels)),
            "penetration": np.zeros((nt + 1, n_wheels)),
            "rail_displacement": np.zeros((nt + 1, n_wheels)),
            "wheel_height": np.zeros((nt + 1, n_wheels)),
            "y": np.zeros((nt + 1, n_dof)), "y_dot": np.zeros((nt + 1, n_dof)),
            "y_ddot": np.zeros((nt + 1, n_dof)),
            "probes": np.zeros((nt + 1, 3, n_probes, 3)),
            "rail": np.zeros((nt + 1,) + tuple(rail_shape)),
        }

    def put(self, n: int, **values) -> None:
        for k, v in values.items():
            if v is not None:
                self.arrays[k][n] = v


# --------------------------------------------------------------------------- the stage
@dataclass(frozen=True)
class TransientOutput(StageOutput):
    """What the ``transient`` stage returns: its run statistics and the numbers the studies
    take from them (the contact forces as the ``mbs`` stage's, per wheel [N]).

    Attributes
    ----------
    n_nodes, n_dofs
        Size of the model.
    dt, n_steps, time_integration
        Time step [s], steps and the time integration's wall time [s].
    peak_rss_gb_total
        Peak memory over all ranks [GB].
    static_wheel_load, peak_contact_force, min_contact_force
        Per wheel [N].
    max_rail_deflection
        Largest rail deflection under a wheel [m].
    loss_of_contact_steps
        Steps in which a wheel lost contact.
    engine
        The time integration's engine (``transient.engine``; ``direct`` for results
        recorded before there were others).
    """

    n_nodes: int
    n_dofs: int
    dt: float
    n_steps: int
    time_integration: float
    peak_rss_gb_total: float
    static_wheel_load: np.ndarray
    peak_contact_force: np.ndarray
    min_contact_force: np.ndarray
    max_rail_deflection: float | None
    loss_of_contact_steps: int
    engine: str = "direct"

    @classmethod
    def of_stats(cls, stats: dict) -> TransientOutput:
        """The output of the run statistics (``stats`` of ``transient.h5``)."""
        def per_wheel(key: str) -> np.ndarray:
            return np.array(stats.get(key, []), dtype=float)

        deflection = stats.get("max_rail_deflection")
        return cls(reused=stats.get("reused"), summary=stats, n_nodes=stats["n_nodes"],
                   n_dofs=stats["n_dofs"], dt=stats["dt"], n_steps=stats["n_steps"],
                   time_integration=stats["time_integration"],
                   peak_rss_gb_total=stats["peak_rss_gb_total"],
                   static_wheel_load=per_wheel("static_wheel_load"),
                   peak_contact_force=per_wheel("peak_contact_force"),
                   min_contact_force=per_wheel("min_contact_force"),
                   max_rail_deflection=None if deflection is None else float(deflection),
                   loss_of_contact_steps=int(stats.get("loss_of_contact_steps", 0)),
                   engine=stats.get("engine", "direct"))


def compute(ctx: StageContext) -> TransientOutput:
    """``railvib transient``: direct time integration of the full model (collective).

    Reuses current results or recomputes them (resuming a current checkpoint); see the
    module notes. ``ctx.options``: ``checkpoint_steps`` (also checkpoint every this many
    steps; tests, the case's interval still applies) and ``stop_after`` (test hook: raise
    :class:`Interrupted` after the first checkpoint at or after this step, as if the run
    had been killed).
    """
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    # the cheap checks first: the reuse checks solve for the static wheel loads
    on_root(lambda: precheck_size(case), comm)       # before the mesh: one line, exit 2
    old = on_root(lambda: previous_results(ctx), comm)
    if old is not None:
        rep.info(f"reusing the transient results in {out_dir} (same model, loads and "
                 "settings)")
        _refresh_stress(case, out_dir, comm, rep)
        return TransientOutput.of_stats({**old, "reused": True})
    if case["mesh.order"] > 1:                      # the spectral soil (docs/spectral.md)
        from .spectral_case import run_spectral_transient

        return TransientOutput.of_stats(run_spectral_transient(ctx))
    return TransientOutput.of_stats(_transient(ctx))


# ----------------------------------------------------------------------------- products
#: The full-order solution's case keys: everything that changes K, M, C, the loads and the
#: time step (no ``[mbs]`` key: it has its own time step and contact loop; of ``[modal]``
#: only the keys that change K, M and C); ``transient.checkpoint_interval`` is how it
#: runs, not what.
TRANSIENT_KEYS: Selection = (
    ("materials", ()), ("sections", ()), ("pads", ()), ("boundary", ()), ("damping", ()),
    ("vehicle", ()), ("train2", ()), ("irregularity", ()), ("load", ()),
    ("transient", ("checkpoint_interval",)), ("modal.lumped_mass", ()),
    ("modal.hex_formulation", ()), ("modal.fix_sleeper_rotations", ()),
    ("modal.fix_rail_rotations_at_pads", ()), ("modal.damping_ratio", ()),
    ("output.dt", ()), ("track.end_stiffness", ()), ("track.end_damping", ())) \
    + RANDOM_FIELD_KEYS
_FIELD_KEYS: Selection = TRANSIENT_KEYS + (("output.window", ()), ("output.float32", ()))
_PROBE_KEYS: Selection = TRANSIENT_KEYS + (("output.probes", ()), ("output.probe_roles", ()),
                                           ("probes", ()))
#: The checkpoint resumes all three products: the union of their keys.
_STATE_KEYS: Selection = _FIELD_KEYS + (("output.probes", ()), ("output.probe_roles", ()),
                                        ("probes", ()))
_FILES = ("mesh.file", "irregularity.file")
#: The rows of the products and the checkpoint: ``fields.h5`` and ``probes.h5`` in the
#: layout of ``reconstruct`` under their own table names (``transient:fields.h5``, ...);
#: each depends on the mesh's case keys too (``extends``).
ROWS = (
    StageFile(HISTORIES, "transient", 2, TRANSIENT_KEYS, (MESH_H5,), (), _FILES,
              check=check_transient, extends=(MESH_H5,), check_context=_checks_context),
    StageFile(FIELDS, "transient", 2, _FIELD_KEYS, (MESH_H5,), (FIELDS_XDMF,), _FILES,
              file=FIELDS_H5, check=check_fields, extends=(MESH_H5,)),
    StageFile(PROBES, "transient", 2, _PROBE_KEYS, (MESH_H5,), (), _FILES, file=PROBES_H5,
              check=check_probes, extends=(MESH_H5,)),
    StageFile(CHECKPOINT, "transient", 2, _STATE_KEYS, (MESH_H5,), (), _FILES,
              check=check_checkpoint, extends=(MESH_H5,)),
)

STAGE = Stage(name="transient", help="direct time integration of the full FE model "
              "(absorbing faces, causal waves)", products=ROWS, reads=(MESH_H5,),
              compute=compute, petsc=True, needs=("mesh",), refuse=spectral_refusals)


def run_transient_stage(case: Case, out_dir: Path, comm, rep: Reporter,
                        petsc_options: list[str] | None = None, *,
                        checkpoint_steps: int | None = None, stop_after: int | None = None
                        ) -> dict:
    """The ``transient`` stage from a script: :data:`STAGE` through the runner (the folder's
    lock, PETSc started with ``petsc_options``; no ``run.json`` entry).

    Parameters
    ----------
    case, out_dir, comm, rep, petsc_options
        As for every stage.
    checkpoint_steps, stop_after
        The test hooks of :func:`compute`.

    Returns
    -------
    dict
        Summary (time step, steps, timings, contact forces, peak memory, ...), ``reused``.
    """
    runner = StageRunner(out_dir, comm, rep, petsc_options or (), command="transient")
    return dict(runner.run(STAGE, case, record=False, checkpoint_steps=checkpoint_steps,
                           stop_after=stop_after).result.summary)


def _transient(ctx: StageContext) -> dict:
    t_wall, out_dir, rep = time.perf_counter(), ctx.out_dir, ctx.rep
    run = setup_run(ctx)
    loop = _start(ctx, run)
    with rep.stage("transient: time integration"), _discard_on_divergence(ctx, loop.writer):
        loop.iterate()
    t_integration = time.perf_counter() - loop.t_run
    _outputs(ctx, run, loop, t_integration, t_wall)
    stats = loop.stats
    run.engine.destroy()
    rep.info(format_summary(stats))
    rep.info(f"wrote {out_dir / FIELDS_H5}, {out_dir / PROBES_H5}, "
             f"{out_dir / TRANSIENT_H5}")
    return {**stats, "reused": False}


def _start(ctx: StageContext, run: TransientRun) -> TimeLoop:
    """The loop of ``run`` at its first step: resumed from a current checkpoint (the
    engine's own state, the layers' memory, restored too) or from the initial state, with
    the fields' writer open (collective)."""
    case, comm, rep, dt, nt = ctx.case, ctx.comm, ctx.rep, run.dt, run.nt
    steps_out, mesh = run.steps_out, run.mesh
    upstream = {MESH_H5: run.mesh_sha}
    recorder = Recorder(nt, run.n_wheels, run.n_dof, len(run.probe_names),
                        run.rails.dofs.shape[:2] + (2,)) if comm.rank == 0 else None
    ckpt_path = ctx.out_dir / CHECKPOINT
    engine_state = bool(run.engine.state())
    run_id = on_root(lambda: _resumable(ctx, run.mesh_sha, (steps_out.size, mesh.n_nodes, 3),
                                        nt, engine_state), comm)
    state = None
    if run_id is not None:
        state, fields_written = _resume(ckpt_path, run, recorder, comm)
        if state is None:
            def drop() -> None:
                ctx.rep.info(f"not resuming from {ckpt_path}: its engine state does not "
                             "match the model's layers; starting at t = 0")
                ctx.discard(ckpt_path)
                resume_path(ctx.out_dir / FIELDS_H5).unlink(missing_ok=True)

            on_root(drop, comm)
            run_id = None
        else:
            rep.info(f"resuming from the checkpoint at step {state.step} of {nt} "
                     f"(t = {state.step * dt:.4f} s)")
    resume_ok = state is not None
    if not resume_ok:
        run_id = on_root(lambda: uuid.uuid4().hex, comm)
        with rep.stage("transient: initial state"):
            state = initial_state(run, comm, rep)
        fields_written = 0

    def fields_attrs() -> dict:
        return {**ctx.provenance(FIELDS, upstream), "run_id": run_id,
                "stride": int(steps_out[1] - steps_out[0]) if steps_out.size > 1 else 1,
                "window": json.dumps(case["output.window"] or None)}

    writer = FieldWriter(ctx.out_dir / FIELDS_H5, comm, mesh, run.dofmap, steps_out * dt,
                         steps_out, case["output.float32"],
                         on_root(fields_attrs, comm) if not resume_ok else {},
                         resume=resume_ok, block=FIELD_BLOCK,
                         extra_bytes=_stress_bytes(case, len(mesh.hexes)))
    run.engine.start(state)
    loop = TimeLoop(ctx, run, state, recorder, writer, run_id, fields_written)
    if not resume_ok:
        loop.record(0)
    return loop


def _resume(path: Path, run: TransientRun, recorder, comm) -> tuple:
    """The state and the output steps written of the checkpoint ``path``, the engine's
    own state restored (collective); ``(None, 0)`` when a rank's part of the engine's
    state is not in it (the run starts at t = 0)."""
    layer = run.engine.state()
    ids = layer["pml_elements"][1] if "pml_elements" in layer else None
    try:
        ck = read_checkpoint(path, run.dofmap.owned_dofs(comm.rank), comm.rank, ids)
        missing = bool(layer) and not set(layer) <= set(ck["engine"])
    except KeyError:
        missing = True
    if comm.allreduce(missing, op=_lor()):
        return None, 0
    run.engine.restore(ck["engine"])
    state = State(ck["step"], ck["u"].copy(), ck["v"].copy(), ck["a"].copy(),
                  ck["y"], ck["y_dot"], ck["y_ddot"], ck["penetration"], ck["force"])
    if comm.rank == 0:
        for k, v in ck["history"].items():
            recorder.arrays[k][...] = v
    return state, ck["fields_written"]


def _lor():
    from mpi4py import MPI

    return MPI.LOR


class TimeLoop:
    """The time loop of a run: step, record, checkpoint (as SPECFEM3D's
    ``iterate_time``); the engine does the physics (:class:`~.engine.Engine`).

    ``ctx.options``: ``checkpoint_steps`` (also checkpoint every this many steps; tests)
    and ``stop_after`` (raise :class:`Interrupted` after the first checkpoint at or after
    this step).
    """

    def __init__(self, ctx: StageContext, run: TransientRun, state: State, recorder,
                 writer: FieldWriter, run_id: str, fields_written: int):
        self.ctx, self.run, self.state, self.recorder = ctx, run, state, recorder
        self.writer, self.run_id, self.fields_written = writer, run_id, fields_written
        self.comm = ctx.comm
        self.out_index = np.full(run.nt + 1, -1, dtype=np.int64)
        self.out_index[run.steps_out] = np.arange(run.steps_out.size)
        self.guard = make_guard(run, ctx.case, state)
        self.first_step = state.step
        self.t_run = time.perf_counter()
        self.stats: dict = {}

    def record(self, n: int, info=None) -> None:
        """The probes, rails, wheels and fields of step ``n`` (collective)."""
        run, state, comm, recorder = self.run, self.state, self.comm, self.recorder
        probes = run.probe_sampler
        part = np.concatenate([probes.sample(state.u, state.v, state.a).ravel(),
                               run.rail_sampler.sample(state.u).ravel()])
        total = part
        if comm.size > 1:
            total = np.zeros_like(part) if comm.rank == 0 else None
            comm.Reduce(part, total, root=0)
        if comm.rank == 0:
            npb = 9 * probes.n
            recorder.put(n, probes=total[:npb].reshape(3, probes.n, 3),
                         rail=total[npb:].reshape(recorder.arrays["rail"].shape[1:]))
            if run.driver is not None:
                recorder.put(n, contact_force=state.force, penetration=state.penetration,
                             y=state.y, y_dot=state.y_dot, y_ddot=state.y_ddot)
                if info is not None and info.rail_displacement is not None:
                    recorder.put(n, rail_displacement=info.rail_displacement,
                                 wheel_height=info.wheel_height)
            elif run.forces is not None:
                recorder.put(n, contact_force=run.forces)
        k = self.out_index[n]
        if k >= self.fields_written:
            self.writer.put(int(k), state.u, state.v, state.a)

    def step(self, state: State) -> StepInfo | None:
        """One step of the engine. A contact Newton iteration that fails (on every rank
        together: the ranks solve the same gathered contact) leaves ``state`` at the last
        step; the guard checks that state at once, so that a run that has grown without
        bound is named as such, where it grows; else the failure is reported with its
        time, its likely cause and what to change."""
        try:
            return self.run.engine.step(state)
        except ContactNewtonError as exc:
            self.guard.check(state)
            raise DivergenceError(
                f"the time integration failed at t = {(state.step + 1) * self.run.dt:.4f} s: "
                f"{exc}; likely cause: a step too large for the Hertz contact's stiffness "
                f"(or a rail that grew without bound since the last check at t = "
                f"{self.guard.last_check_time:.4f} s); change: a smaller transient.dt; "
                "nothing was written as a result") from exc

    def iterate(self) -> None:
        """Step to the end, recording every step and checkpointing as asked."""
        ctx, run, state, comm = self.ctx, self.run, self.state, self.comm
        nt, dt = run.nt, run.dt
        interval = ctx.case["transient.checkpoint_interval"]
        every, stop_after = map(ctx.options.get, ("checkpoint_steps", "stop_after"))
        last_progress = last_ckpt = self.t_run
        while state.step < nt:
            info = self.step(state)
            if self.guard.due(state.step, state.step == nt):
                self.guard.check(state)             # before anything of this step is kept
            self.record(state.step, info)
            now = time.perf_counter()
            if comm.rank == 0 and (now - last_progress >= 2.0 or state.step == nt):
                last_progress = now
                done = state.step - self.first_step
                ctx.rep.progress(f"transient: step {state.step}/{nt} (t = "
                                 f"{state.step * dt:.4f} s, "
                                 f"{done / max(now - self.t_run, 1e-9):.1f} steps/s)",
                                 done, nt - self.first_step, self.t_run)
            want = (interval > 0 and now - last_ckpt >= interval) or \
                (every is not None and state.step % every == 0)
            want = comm.bcast(want, root=0) if comm.size > 1 else want
            if want and state.step < nt:
                self.checkpoint()
                last_ckpt = time.perf_counter()
                if stop_after is not None and state.step >= stop_after:
                    self.writer.close()
                    raise Interrupted(f"stopped after the checkpoint at step {state.step}")

    def checkpoint(self) -> None:
        """``transient_checkpoint.h5`` after this step: the fields on disk up to it, then
        the state, the engine's own state (the layers' memory) and the histories
        (collective)."""
        ctx, run, state, comm = self.ctx, self.run, self.state, self.comm
        self.writer.sync()
        self.fields_written = int(np.searchsorted(run.steps_out, state.step, "right"))
        rows = run.dofmap.owned_dofs(comm.rank)
        engine = gather_state(run.engine.state(), comm, rows, run.dofmap.n_dofs)
        attrs = ({**ctx.provenance(CHECKPOINT, {MESH_H5: run.mesh_sha}),
                  "run_id": self.run_id} if comm.rank == 0 else None)
        small = {"y": state.y, "y_dot": state.y_dot, "y_ddot": state.y_ddot,
                 "penetration": state.penetration, "force": state.force}
        write_checkpoint(ctx.out_dir / CHECKPOINT, comm, attrs, state.step,
                         self.fields_written, {"u": state.u, "v": state.v, "a": state.a},
                         rows, run.dofmap.n_dofs, small,
                         self.recorder.arrays if comm.rank == 0 else None, engine)


def _outputs(ctx: StageContext, run: TransientRun, loop: TimeLoop, t_integration: float,
             t_wall: float) -> None:
    """fields.h5 (+ /stress), probes.h5, transient.h5 (last), then the checkpoint goes;
    the run statistics in ``loop.stats`` (collective)."""
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    upstream = {MESH_H5: run.mesh_sha}
    with rep.stage("transient: fields, stresses"):
        stress = None
        if case["output.stress_times"]:
            stress = _stress_writer(case, comm, rep, on_root(lambda: stress_key(case), comm))
        loop.writer.finish(stress)
        if not case["output.stress_times"] and comm.rank == 0:
            remove_xdmf(out_dir / STRESS_XDMF)
    rss = comm.allgather(peak_memory_gb())
    stats = _stats(run, t_integration, time.perf_counter() - t_wall, rss, loop.recorder,
                   run.nt - loop.first_step, comm)
    stats["guard"] = loop.guard.stats(run.dofmap.n_dofs)
    stats["resolved_up_to_hz"] = run.resolved_up_to_hz
    rep.info(loop.guard.summary(run.dofmap.n_dofs))
    with rep.stage("transient: probes, histories"):
        def write_rank0() -> None:
            _write_probes(out_dir, run, loop.recorder, case, ctx.provenance(PROBES, upstream))
            _write_histories(out_dir / TRANSIENT_H5, case, run, loop.recorder, stats,
                             ctx.provenance(HISTORIES, upstream))
            ctx.discard(out_dir / CHECKPOINT)

        on_root(write_rank0, comm)
    loop.stats = stats


@contextlib.contextmanager
def _discard_on_divergence(ctx: StageContext, writer: FieldWriter):
    """On a :class:`~railvib_hpc.errors.DivergenceError` (raised on every rank
    together): close and delete the partial ``fields.h5`` and the checkpoint, so that
    nothing of the diverged run looks like a result or is resumed by a rerun."""
    try:
        yield
    except DivergenceError:
        writer.pending = []                # (the checked steps only; nothing more to write)
        writer.close()

        def remove() -> None:
            writer.path.unlink(missing_ok=True)
            ctx.discard(ctx.out_dir / CHECKPOINT)

        on_root(remove, ctx.comm)
        raise


def make_guard(run: TransientRun, case: Case, state: State):
    """The run's :class:`~.guard.DivergenceGuard`, started from ``state``: the regions of
    this rank's rows (parts and perfectly matched layers), checked every output stride of
    steps at first (collective)."""
    from .guard import DivergenceGuard, dof_regions, node_regions

    mesh, dofmap, system = run.mesh, run.dofmap, run.system
    layers = []
    if run.pml is not None:
        centres = mesh.points[mesh.hexes].mean(axis=1)
        thickness = case["boundary.layer_thickness"]
        for face in run.pml[0]:
            layers.append((face.face, np.abs(centres[:, face.axis] - face.plane) < thickness))
    region, names = node_regions(mesh, layers)
    r0, r1 = system.r0, system.r1
    rows = dof_regions(region, dofmap.index, r0, r1)
    steps = run.steps_out
    stride = int(steps[1] - steps[0]) if steps.size > 1 else run.nt
    guard = DivergenceGuard(system, run.solver, rows, names, mesh.points, dofmap.index,
                            run.dt, run.engine.name, run.engine.allowed_step, stride)
    guard.start(state)
    return guard


def _stress_writer(case: Case, comm, rep: Reporter, key: str):
    """``write(path)``: ``/stress`` at ``output.stress_times`` into ``path`` (collective) with
    the stress writer of ``reconstruct`` (``stress.xdmf`` names the final ``fields.h5``)."""
    from ..reconstruct.stress import hex_materials, stress_from_fields

    materials = hex_materials(Problem.from_case(case))

    def write(path: Path) -> None:
        stats = stress_from_fields(path, comm, case["output.stress_times"], materials, rep=rep,
                                   attrs={"inputs_sha256": key},
                                   require_complete=path.name == FIELDS_H5)
        rep.info(f"  stresses at {stats['n_times']} time(s), max von Mises "
                 f"{stats['max_von_mises'] / 1e3:.3f} kPa")

    return write


def _stats(run: TransientRun, t_integration, t_wall, rss, recorder, n_done, comm) -> dict:
    system, solver, engine = run.system, run.solver, run.engine
    nt = run.nt
    stats = {"solver": "transient", "dt": run.dt, "n_steps": nt, "steps_run": n_done,
             "t_end": nt * run.dt, "n_dofs": run.dofmap.n_dofs,
             "n_nodes": run.mesh.n_nodes, "ranks": comm.size,
             "engine": engine.name,
             "rho_inf": engine.scheme.rho_inf if engine.scheme is not None else None,
             "damping": engine.damping,
             "time_integration": t_integration, "time_total": t_wall,
             "steps_per_second": n_done / max(t_integration, 1e-9),
             "time_factorization": system.time_factorization,
             "time_solves": system.time_solves, "time_products": system.time_products,
             "time_contact": solver.time_contact, "solves": system.n_solves,
             "time_pml": engine.time_pml,
             "pml_elements": (0 if engine.layer is None
                              else comm.allreduce(engine.layer.n_elements)),
             "factor_memory_gb": system.factor_memory_gb, "out_of_core": system.out_of_core,
             "peak_rss_gb_per_rank": rss, "peak_rss_gb_total": float(sum(rss))}
    if run.columns is not None:
        stats["rail_columns"] = run.columns.n_computed
        stats["time_rail_columns"] = run.columns.time
    if comm.rank == 0 and run.n_wheels:
        f = recorder.arrays["contact_force"]
        x = run.x
        lo, hi = float(run.rails.x.min()), float(run.rails.x.max())
        on = (x >= lo) & (x <= hi)
        stats["static_wheel_load"] = (run.vehicle.static_wheel_loads().tolist()
                                      if run.vehicle is not None else f[0].tolist())
        stats["mean_contact_force"] = [float(f[on[:, j], j].mean()) if on[:, j].any()
                                       else math.nan for j in range(f.shape[1])]
        stats["peak_contact_force"] = f.max(axis=0).tolist()
        stats["min_contact_force"] = f.min(axis=0).tolist()
        stats["loss_of_contact_steps"] = (int(np.any(f <= 0.0, axis=1)[1:].sum())
                                          if run.vehicle is not None else 0)
        stats["max_rail_deflection"] = float(-recorder.arrays["rail_displacement"].min())
    return comm.bcast(stats if comm.rank == 0 else None, root=0) if comm.size > 1 else stats


def format_summary(stats: dict) -> str:
    """Printable run statistics and contact forces."""
    lines = [f"transient: {stats['n_dofs']:,} DOFs, dt = {stats['dt']:.3e} s, "
             f"{stats['steps_run']} steps in {stats['time_integration']:.1f} s "
             f"({stats['steps_per_second']:.1f} steps/s; solves {stats['time_solves']:.1f} s, "
             f"products {stats['time_products']:.1f} s, contact {stats['time_contact']:.1f} s),"
             f" factorization {stats['time_factorization']:.1f} s, peak memory "
             f"{stats['peak_rss_gb_total']:.2f} GB (all ranks)"]
    if "peak_contact_force" in stats:
        lines.append("  wheel  static [kN]  mean on flexible rail [kN]  peak [kN]  min [kN]")
        for j, (s, mu, pk, lo) in enumerate(zip(stats["static_wheel_load"],
                                                stats["mean_contact_force"],
                                                stats["peak_contact_force"],
                                                stats["min_contact_force"])):
            lines.append(f"  {j:5d}  {s / 1e3:11.3f}  {mu / 1e3:26.3f}  {pk / 1e3:9.3f}  "
                         f"{lo / 1e3:8.3f}")
        lines.append(f"  steps with a wheel off the rail: {stats['loss_of_contact_steps']}; "
                     f"max rail deflection under a wheel "
                     f"{stats['max_rail_deflection'] * 1e3:.4f} mm")
    return "\n".join(lines)


def _write_probes(out_dir: Path, run: TransientRun, recorder: Recorder, case: Case,
                  prov: dict) -> None:
    """probes.h5 + probes/*.csv (layout of reconstruct, with the probes' roles) and the rail
    bending moments (rank 0)."""
    from ..fem.beam import shear_deformation_factors
    from ..io.formats.probes import write_probes_csv, write_probes_h5
    from ..reconstruct.stress import rail_bending_moment, rail_section
    from ..schema import DEFAULT_PROBE_ROLE

    t = run.times
    pr = recorder.arrays["probes"]
    hist = {}
    sampler = run.probe_sampler
    mesh = run.mesh
    user_roles = list(case["output.probe_roles"])
    lines = line_probes(case)
    for i, name in enumerate(run.probe_names):
        if name in mesh.probes:
            role = mesh.probe_roles.get(name, DEFAULT_PROBE_ROLE)
        elif name in lines:
            role = "free_field"
        else:
            k = int(name.rsplit("_", 1)[1]) - 1
            role = user_roles[k] if k < len(user_roles) else DEFAULT_PROBE_ROLE
        hist[name] = {"t": t, "displacement": pr[:, 0, i], "velocity": pr[:, 1, i],
                      "acceleration": pr[:, 2, i], "coords": run.probe_coords[i],
                      "element": np.int64(sampler.elem[i]), "xi": sampler.xi[i],
                      "role": role}
    attrs = {**prov, "solver": "transient"}
    rails = run.rails
    if not rails.nodes.shape[0]:             # no track (track.count = 0): no rail group
        write_probes_h5(out_dir / PROBES_H5, hist, attrs=attrs, groups={})
        write_probes_csv(out_dir / PROBES_CSV_DIR, hist)
        return
    sec = rail_section(run.problem)
    rail = recorder.arrays["rail"]                                # (nt+1, 2, k, 2)
    moments, ends = [], []
    for r in range(2):
        seg = np.stack([mesh.points[rails.nodes[r, :-1]], mesh.points[rails.nodes[r, 1:]]],
                       axis=1)
        phi_y, _ = shear_deformation_factors(seg, sec["E"], sec["G"], sec["A"], sec["I"],
                                             sec["I"], sec["k"], sec["k"])
        m_el = rail_bending_moment(rails.x[r], rail[:, r, :, 0], rail[:, r, :, 1], sec["EI"],
                                   phi_y, per_element=True)
        ends.append(m_el)
        moments.append(rail_bending_moment(rails.x[r], rail[:, r, :, 0], rail[:, r, :, 1],
                                           sec["EI"], phi_y))
    groups = {"rail": {"time": t, "x": rails.x, "y": rails.y, "nodes": rails.nodes,
                       "bending_moment": np.stack(moments, axis=1),
                       "bending_moment_ends": np.stack(ends, axis=1)}}
    attrs = {**attrs,
             "rail_moment_sign": "sagging positive (M = E I dpsi/dx, psi = -ry)",
             "rail_moment_static_correction_included": 1}
    write_probes_h5(out_dir / PROBES_H5, hist, attrs=attrs, groups=groups)
    write_probes_csv(out_dir / PROBES_CSV_DIR, hist)


def _write_histories(path: Path, case: Case, run: TransientRun, recorder: Recorder,
                     stats: dict,
                     prov: dict) -> None:
    """``transient.h5`` (rank 0; checked, atomic, recorded) of the run's recorder and setup
    (:func:`~railvib_hpc.io.formats.transient.write_transient_h5`)."""
    a = recorder.arrays
    vehicle = run.vehicle
    context = _checks_context(case)
    write_transient_h5(path, stats=stats, provenance=prov,
                       check=lambda tmp: check_transient(tmp, True, context),
                       time=run.times, wheel_x=run.x,
                       rail_index=run.passage["wheel_rail"],
                       histories={k: v for k, v in a.items() if k not in ("probes", "rail")},
                       dof_names=list(vehicle.dof_names) if vehicle is not None else [],
                       vehicle_type=("surface_load" if uses_surface_load(case)
                                     else case["vehicle.type"]), rail_x=run.rails.x,
                       rail=a["rail"])


def _write_checkpoint(path: Path, comm, attrs: dict | None, fields_written: int,
                      state: State, dofmap, history: dict | None) -> None:
    """``transient_checkpoint.h5`` of the state after ``state.step`` (collective; this
    rank's rows of the state vectors by global DOF number,
    :func:`~railvib_hpc.io.formats.transient.write_checkpoint`)."""
    small = {"y": state.y, "y_dot": state.y_dot, "y_ddot": state.y_ddot,
             "penetration": state.penetration, "force": state.force}
    write_checkpoint(path, comm, attrs, state.step, fields_written,
                     {"u": state.u, "v": state.v, "a": state.a},
                     dofmap.owned_dofs(comm.rank), dofmap.n_dofs, small, history)
