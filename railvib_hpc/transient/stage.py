"""The ``transient`` stage: direct time integration of the full finite-element model.

``railvib transient CASE`` (collective) builds the same model as the modal stage (mesh,
DOFs with the ``[boundary]`` conditions, K and M), adds the damping matrix C of
``[damping]`` and the absorbing faces' dashpots, and integrates ``M u'' + C u' + K u = f``
with the generalized-alpha scheme (:mod:`.scheme`; ``transient.rho_inf = 1``: Newmark
average acceleration) on one MUMPS factor of the effective matrix. The loads are the
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
(:class:`~.integrate.RailColumns`). On several ranks MUMPS's parallel factorization is
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
from ..errors import ResourceError
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
from ..resources import check_memory, peak_memory_gb
from ..site import line_probes
from .engines import (  # TransientInputError re-exported
    TransientInputError,
    assemble_matrices,
    check_implicit_outside_layers,
    explicit_system,
    imex_partition,
    initial_state,
    pml_layer,
)
from .integrate import DirectSolver, RailColumns, State, VehicleDriver
from .output import FieldWriter, PointSampler, RailSampler
from .rail import RailDofs, WheelCoupling
from .scheme import GeneralizedAlpha, choose_time_step, coarse_step_warning
from .spectral_refusals import spectral_refusals
from .surface_case import (
    element_time,
    no_rails,
    surface_load,
    surface_passage,
    uses_surface_load,
)

#: Table names of the products (:data:`railvib_hpc.io.products.STAGE_FILES`), in the
#: order they are checked (the solution first; it is written last).
FIELDS, PROBES, HISTORIES = TRANSIENT_FIELDS, TRANSIENT_PROBES, TRANSIENT_H5
PRODUCTS = (HISTORIES, FIELDS, PROBES)
CHECKPOINT = TRANSIENT_CHECKPOINT_H5
#: Output steps buffered per collective write of fields.h5.
FIELD_BLOCK = 16
#: Rail nodes ahead of each wheel whose columns are computed in one block.
LOOKAHEAD_NODES = 12
#: Largest number of time steps of one run: 100 times the thesis passage's 1840 steps,
#: about 7.5 hours at the 7.4 steps/s measured for the thesis model on 2 ranks
#: (docs/transient.md). Checked before anything is built or allocated
#: (:func:`check_run_size`).
MAX_TRANSIENT_STEPS = 200_000
#: Copies of rank 0's histories held at once at the end of a run (the histories and the
#: rail bending moments and file buffers computed from them while the files are written).
HISTORY_COPIES = 2


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
        _check_stress_times(case, stored.times())
        n_hexes = stored.n_hexes()
        ensure_space(out_dir, _stress_bytes(case, n_hexes), "the stresses of fields.h5")
        return n_hexes

    with rep.stage("transient: stresses"):
        on_root(check_times, comm)
        _stress_writer(case, comm, rep, key)(fields)    # rewritten in place: record again
        record_file(fields, comm)


def _check_stress_times(case: Case, t_out: np.ndarray) -> None:
    times = [float(v) for v in case["output.stress_times"]]
    tol = 1e-9 * max(1.0, float(np.abs(t_out).max()))
    bad = [v for v in times if v < t_out[0] - tol or v > t_out[-1] + tol]
    if bad:
        raise TransientInputError(f"output.stress_times = {times}: {bad} outside the stored "
                                  f"time range [{t_out[0]:.6g}, {t_out[-1]:.6g}] s of "
                                  "fields.h5 (output.window)")


def _stress_bytes(case: Case, n_hexes: int) -> int:
    n = len(case["output.stress_times"])
    return 16 * n * int(n_hexes) + 16 * n


def _resumable(ctx: StageContext, mesh_sha: str, n_fields: tuple, nt: int) -> str | None:
    """The run id of a checkpoint this run may resume, or None (rank 0).

    The checkpoint must be current for the case and computed from this ``mesh.h5``,
    unchanged and sound (:func:`~railvib_hpc.io.provenance.examine`), and the partial
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
        return run_id

    old = ctx.reuse(CHECKPOINT, accept=matching, upstream={MESH_H5: mesh_sha},
                    stale=lambda ckpt, why: f"not resuming from {ckpt}: {why}; starting at "
                                            "t = 0")
    if old.ok:
        return old.value
    partial.unlink(missing_ok=True)
    return None


# --------------------------------------------------------------------------- setup
def history_bytes(nt: int, n_wheels: int, n_dof: int, n_probes: int, n_rails: int,
                  n_rail_nodes: int) -> float:
    """Rank 0's memory for the per-step histories of a run of ``nt`` steps [bytes].

    Parameters
    ----------
    nt
        Time steps.
    n_wheels, n_dof
        Wheels (or moving forces) and vehicle DOFs.
    n_probes
        Probes (mesh probes and ``output.probes``).
    n_rails, n_rail_nodes
        Flexible rails and nodes per rail.

    Returns
    -------
    float
        The :class:`Recorder`'s arrays, the times, wheel positions and output index,
        times :data:`HISTORY_COPIES`.
    """
    per_step = (4 * n_wheels + 3 * n_dof + 9 * n_probes + 2 * n_rails * n_rail_nodes
                + n_wheels + 2)
    return HISTORY_COPIES * 8.0 * (nt + 1) * per_step


def check_run_size(case: Case, run: dict, dt: float, how: str, n_wheels: int, n_dof: int,
                   n_probes: int, n_rails: int, n_rail_nodes: int) -> int:
    """Refuse a run with too many steps or histories larger than the memory (one line).

    Parameters
    ----------
    case
        The case.
    run
        :func:`~railvib_hpc.mbs.case_vehicle.passage` of the case.
    dt
        The time step (or an upper bound of it: the count is then a lower bound).
    how
        Where ``dt`` comes from, for the message (``transient.dt = 1e-07 s``).
    n_wheels, n_dof, n_probes, n_rails, n_rail_nodes
        Sizes of the histories (:func:`history_bytes`).

    Returns
    -------
    int
        The number of steps.

    Raises
    ------
    ResourceError
        More than :data:`MAX_TRANSIENT_STEPS` steps, or histories beyond the available
        memory (:func:`~railvib_hpc.resources.check_memory`).
    """
    from ..mbs.results import n_steps

    sec = "load" if uses_surface_load(case) else "vehicle"
    what = "load" if sec == "load" else "wheel"
    t_end, t_after = run["t_end"], case[f"{sec}.t_after"]
    nt = n_steps(t_end, dt)
    advice = (f"shorten the passage ({sec}.t_after, {sec}.x_start, {sec}.x_end"
              + (", train2.t_start" if sec == "vehicle" else "")
              + ") or use a larger transient.dt (0 = automatic)")
    if nt > MAX_TRANSIENT_STEPS:
        raise ResourceError(
            f"the passage lasts {t_end:.4g} s ({t_end - t_after:.4g} s until the last {what} "
            f"reaches x = {run['x_end']:g} m at up to {float(np.abs(run['speeds']).max()):g} "
            f"m/s, then {sec}.t_after = {t_after:g} s): {nt:.3g} steps of {how}, more than "
            f"the limit of {MAX_TRANSIENT_STEPS:,} (about 7.5 hours at thesis size); "
            + advice)
    need = history_bytes(nt, n_wheels, n_dof, n_probes, n_rails, n_rail_nodes)
    check_memory(need, f"the transient histories ({nt:.3g} steps)", advice)
    return nt


def precheck_size(case: Case) -> None:
    """:func:`check_run_size` from the case and its layout alone, before the mesh is built.

    The automatic step is bounded above by the band and ``output.dt`` (the rail elements
    can only shorten it), so the count is a lower bound of the run's: a refusal here is
    one the exact check after the mesh would give too.
    """
    from ..mbs.case_vehicle import build_vehicle, passage
    from ..mesh.layout import build_layout

    lay = build_layout(case)
    if uses_surface_load(case):
        vehicle, run = None, surface_passage(case)
    else:
        vehicle = build_vehicle(case)
        run = passage(case, vehicle, float(np.max(lay.sleeper_x)))
    if not run["t_end"] > 0:
        return                      # an empty passage: refused later with its own message
    tr = case["transient"]
    if tr["dt"] > 0:
        dt, how = tr["dt"], f"transient.dt = {tr['dt']:g} s"
    else:
        dt = choose_time_step(tr["f_max"], tr["steps_per_period"], case["output.dt"])
        how = f"the automatic step (at most {dt:.3g} s)"
    n_user = np.asarray(case["output.probes"], dtype=float).reshape(-1, 3).shape[0] \
        + len(line_probes(case))
    n_rail_nodes = lay.rail_div * max(len(lay.sleeper_x) - 1, 1) + 1
    check_run_size(case, run, dt, how, run["wheel_rail"].size,
                   0 if vehicle is None else vehicle.n_dof, len(lay.probes) + n_user,
                   len(lay.rail_y), n_rail_nodes)


def time_step(case: Case, element_time: float, rep: Reporter) -> float:
    """``transient.dt`` or the automatic step; warns when it is too coarse for the band."""
    tr = case["transient"]
    if tr["dt"] > 0:
        dt = tr["dt"]
    else:
        dt = choose_time_step(tr["f_max"], tr["steps_per_period"], case["output.dt"],
                              element_time, tr["steps_per_element"])
    warning = coarse_step_warning(dt, tr["f_max"], tr["steps_per_period"], tr["rho_inf"])
    if warning:
        rep.info(warning)
    return dt


def output_steps(case: Case, dt: float, nt: int) -> np.ndarray:
    """Steps written to ``fields.h5``: every ``output.dt`` within ``output.window``."""
    stride = max(1, int(round(case["output.dt"] / dt))) if case["output.dt"] > 0 else 1
    steps = np.arange(0, nt + 1, stride)
    w = case["output.window"]
    if w:
        t = steps * dt
        tol = 1e-9 * max(1.0, w[1])
        steps = steps[(t >= w[0] - tol) & (t <= w[1] + tol)]
    if steps.size == 0:
        raise TransientInputError(f"output.window = {w} contains no output step of the run "
                                  f"(0 .. {nt * dt:.4g} s)")
    return steps


def probe_points(mesh, case: Case) -> tuple[list[str], np.ndarray]:
    """Names and coordinates: the mesh probes, then ``output.probes`` (``user_1``, ...),
    then the points of the probe lines (:func:`railvib_hpc.site.line_probes`)."""
    names = list(mesh.probes)
    coords = [mesh.probes[k] for k in names]
    user = np.asarray(case["output.probes"], dtype=float).reshape(-1, 3)
    for i, p in enumerate(user):
        names.append(f"user_{i + 1}")
        coords.append(p)
    for name, point in line_probes(case).items():
        names.append(name)
        coords.append(point.point)
    return names, np.asarray(coords, dtype=float).reshape(-1, 3)


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
    t_wall, case, out_dir, comm, rep = time.perf_counter(), ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    checkpoint_steps, stop_after = map(ctx.options.get, ("checkpoint_steps", "stop_after"))
    init = _setup(ctx)
    mesh, dofmap, system, solver = init["mesh"], init["dofmap"], init["system"], init["solver"]
    nt, dt, steps_out = init["nt"], init["dt"], init["steps_out"]
    upstream = {MESH_H5: init["mesh_sha"]}
    recorder = Recorder(nt, init["n_wheels"], init["n_dof"], len(init["probe_names"]),
                        init["rails"].dofs.shape[:2] + (2,)) if comm.rank == 0 else None
    out_index = np.full(nt + 1, -1, dtype=np.int64)
    out_index[steps_out] = np.arange(steps_out.size)
    ckpt_path = out_dir / CHECKPOINT

    # ---- initial state or resume
    # the perfectly matched layers' memory is not checkpointed: such a run starts at t = 0
    layers = getattr(system, "pml", None) is not None
    run_id = None if layers else on_root(lambda: _resumable(
        ctx, init["mesh_sha"], (steps_out.size, mesh.n_nodes, 3), nt), comm)
    resume_ok = run_id is not None
    if resume_ok:
        ck = read_checkpoint(ckpt_path, dofmap.owned_dofs(comm.rank), comm.rank)
        state = State(ck["step"], ck["u"].copy(), ck["v"].copy(), ck["a"].copy(),
                      ck["y"], ck["y_dot"], ck["y_ddot"], ck["penetration"], ck["force"])
        if comm.rank == 0:
            for k, v in ck["history"].items():
                recorder.arrays[k][...] = v
        fields_written = ck["fields_written"]
        rep.info(f"resuming from the checkpoint at step {state.step} of {nt} "
                 f"(t = {state.step * dt:.4f} s)")
    else:
        run_id = on_root(lambda: uuid.uuid4().hex, comm)
        with rep.stage("transient: initial state"):
            state = initial_state(init, comm, rep)
        fields_written = 0

    def fields_attrs() -> dict:
        return {**ctx.provenance(FIELDS, upstream), "run_id": run_id,
                "stride": int(steps_out[1] - steps_out[0]) if steps_out.size > 1 else 1,
                "window": json.dumps(case["output.window"] or None)}

    writer = FieldWriter(out_dir / FIELDS_H5, comm, mesh, dofmap, steps_out * dt, steps_out,
                         case["output.float32"],
                         on_root(fields_attrs, comm) if not resume_ok else {},
                         resume=resume_ok, block=FIELD_BLOCK,
                         extra_bytes=_stress_bytes(case, len(mesh.hexes)))
    solver.start(state)
    guard = make_guard(init, case, state)
    probes, rails_s = init["probe_sampler"], init["rail_sampler"]

    def record(n: int, info=None) -> None:
        part = np.concatenate([probes.sample(state.u, state.v, state.a).ravel(),
                               rails_s.sample(state.u).ravel()])
        total = part
        if comm.size > 1:
            total = np.zeros_like(part) if comm.rank == 0 else None
            comm.Reduce(part, total, root=0)
        if comm.rank == 0:
            npb = 9 * probes.n
            recorder.put(n, probes=total[:npb].reshape(3, probes.n, 3),
                         rail=total[npb:].reshape(recorder.arrays["rail"].shape[1:]))
            if init["driver"] is not None:
                recorder.put(n, contact_force=state.force, penetration=state.penetration,
                             y=state.y, y_dot=state.y_dot, y_ddot=state.y_ddot)
                if info is not None and info.rail_displacement is not None:
                    recorder.put(n, rail_displacement=info.rail_displacement,
                                 wheel_height=info.wheel_height)
            elif init["forces"] is not None:
                recorder.put(n, contact_force=init["forces"])
        k = out_index[n]
        if k >= fields_written_box[0]:
            writer.put(int(k), state.u, state.v, state.a)

    def checkpoint_attrs() -> dict:
        return {**ctx.provenance(CHECKPOINT, upstream), "run_id": run_id}

    fields_written_box = [fields_written]
    if not resume_ok:
        record(0, init.get("info0"))
    interval = case["transient.checkpoint_interval"]
    if layers and (interval > 0 or checkpoint_steps is not None):
        rep.info("  checkpoints: none written (the perfectly matched layers' memory is not in "
                 "them): an interrupted run starts again at t = 0")
    t_run = time.perf_counter()
    last_progress = last_ckpt = t_run
    first_step = state.step
    with rep.stage("transient: time integration"), _discard_on_divergence(ctx, writer):
        while state.step < nt:
            info = solver.step(state)
            if guard.due(state.step, state.step == nt):
                guard.check(state)             # before anything of this step is kept
            record(state.step, info)
            now = time.perf_counter()
            if comm.rank == 0 and (now - last_progress >= 2.0 or state.step == nt):
                last_progress = now
                done = state.step - first_step
                rep.progress(f"transient: step {state.step}/{nt} (t = {state.step * dt:.4f} s, "
                             f"{done / max(now - t_run, 1e-9):.1f} steps/s)",
                             done, nt - first_step, t_run)
            want = (interval > 0 and now - last_ckpt >= interval) or \
                (checkpoint_steps is not None and state.step % checkpoint_steps == 0)
            want = comm.bcast(want, root=0) if comm.size > 1 else want
            if want and state.step < nt and not layers:
                writer.sync()          # the fields on disk up to this step, then the state
                fields_written_box[0] = int(np.searchsorted(steps_out, state.step, "right"))
                _write_checkpoint(ckpt_path, comm,
                                  checkpoint_attrs() if comm.rank == 0 else None,
                                  fields_written_box[0], state, dofmap,
                                  recorder.arrays if comm.rank == 0 else None)
                last_ckpt = time.perf_counter()
                if stop_after is not None and state.step >= stop_after:
                    writer.close()
                    raise Interrupted(f"stopped after the checkpoint at step {state.step}")
    t_integration = time.perf_counter() - t_run

    # ---- outputs: fields.h5 (+ /stress), probes.h5, transient.h5 (last), then the
    # checkpoint goes
    with rep.stage("transient: fields, stresses"):
        stress = None
        if case["output.stress_times"]:
            stress = _stress_writer(case, comm, rep, on_root(lambda: stress_key(case), comm))
        writer.finish(stress)
        if not case["output.stress_times"] and comm.rank == 0:
            remove_xdmf(out_dir / STRESS_XDMF)
    rss = comm.allgather(peak_memory_gb())
    stats = _stats(init, system, solver, t_integration, time.perf_counter() - t_wall, rss,
                   recorder, nt - first_step, comm)
    stats["guard"] = guard.stats(dofmap.n_dofs)
    stats["resolved_up_to_hz"] = init["resolved_up_to_hz"]
    rep.info(guard.summary(dofmap.n_dofs))
    with rep.stage("transient: probes, histories"):
        def write_rank0() -> None:
            _write_probes(out_dir, init, recorder, case, ctx.provenance(PROBES, upstream))
            _write_histories(out_dir / TRANSIENT_H5, case, init, recorder, stats,
                             ctx.provenance(HISTORIES, upstream))
            ctx.discard(ckpt_path)

        on_root(write_rank0, comm)
    solver.destroy()
    system.destroy()
    for A in (init["K"], init["M"]):
        if A is not None:
            A.destroy()
    from ..model.petsc import destroy_damping

    destroy_damping(init["C"])
    rep.info(format_summary(stats))
    rep.info(f"wrote {out_dir / FIELDS_H5}, {out_dir / PROBES_H5}, "
             f"{out_dir / TRANSIENT_H5}")
    return {**stats, "reused": False}


@contextlib.contextmanager
def _discard_on_divergence(ctx: StageContext, writer: FieldWriter):
    """On a :class:`~railvib_hpc.errors.DivergenceError` (raised on every rank
    together): close and delete the partial ``fields.h5`` and the checkpoint, so that
    nothing of the diverged run looks like a result or is resumed by a rerun."""
    from ..errors import DivergenceError

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


def _passage(case: Case, mesh, dofmap) -> tuple:
    """The rails, the vehicle (None: moving forces) and the passage
    (:func:`~railvib_hpc.mbs.case_vehicle.passage`); with ``track.count = 0`` no rail, no
    vehicle and the surface load's passage (:func:`.surface_case.surface_passage`)."""
    from ..mbs.case_vehicle import build_vehicle, passage

    if uses_surface_load(case):
        return no_rails(), None, surface_passage(case)
    try:
        rails = RailDofs.from_mesh(mesh, dofmap.index)
    except ValueError as exc:
        raise TransientInputError(f"railvib transient: {exc}") from None
    vehicle = build_vehicle(case)
    return rails, vehicle, passage(case, vehicle, float(rails.x.max()))


def _mesh_input(ctx: StageContext):
    """The mesh the runner hands over (``ctx.input("mesh")``: ``mesh.h5`` built or reused)
    and its digest (rank 0)."""
    given = ctx.input("mesh")
    return given.value, given.sha256


def _setup(ctx: StageContext) -> dict:
    """Mesh, DOFs, loads, time step, matrices, factor, samplers (collective)."""
    from ..mbs.case_vehicle import passage_irregularity
    from ..model.boundary import boundary_summary, layer_line, problem_dofmap, support_warning
    from .petsc import TransientSystem

    case, comm, rep = ctx.case, ctx.comm, ctx.rep
    with rep.stage("transient: mesh"):
        mesh, mesh_sha = on_root(lambda: _mesh_input(ctx), comm)
    with rep.stage("transient: dofs"):
        problem = Problem.from_case(case)
        dofmap = problem_dofmap(mesh, problem, comm.size)
        rep.info(f"  {mesh.n_nodes} nodes, {dofmap.n_dofs} free DOFs on {comm.size} rank(s); "
                 "faces: " + ", ".join(f"{k} {v['type']}" for k, v in
                                       boundary_summary(mesh, problem).items()))
        layers = layer_line(mesh, problem)
        if layers:
            rep.info(f"  {layers}")
        from .pml import pml_faces, pml_geometry

        # the layers' faces and elements, checked once (a layer the mesh cannot carry is
        # refused before assembly); assembly and the layer's kernel take them from here
        pml = pml_geometry(mesh, problem) if pml_faces(problem) else None
        if pml is not None and case["transient.engine"] == "imex":
            check_implicit_outside_layers(case, mesh, pml[1])
        unsupported = support_warning(mesh, problem)
        if unsupported:
            rep.info(unsupported)
    surface = uses_surface_load(case)     # track.count = 0: [load] on the bare soil
    rails, vehicle, run = _passage(case, mesh, dofmap)
    speed = float(np.max(np.abs(run["speeds"])))
    critical = speed_warning(case, speed)
    if critical:
        rep.info(critical)
    crossing = (element_time(mesh, speed) if surface
                else float(np.diff(rails.x, axis=1).min()) / speed)
    dt = time_step(case, crossing, rep)
    engine = case["transient.engine"]
    explicit = engine == "explicit"
    if engine != "direct":
        # the step follows from the matrices: assemble first
        K, M, C, cinfo, dashpots, problem = assemble_matrices(ctx, mesh, dofmap, problem,
                                                              pml)
        with rep.stage("transient: stability limit"):
            if explicit:
                system, dt, limit = explicit_system(ctx, mesh, dofmap, problem, rails,
                                                     vehicle, (K, M, C, dashpots), dt, pml)
                allowed = system.allowed_step
            else:
                partition, dt, limit, layer, allowed = imex_partition(ctx, mesh, dofmap,
                                                                       problem, K, M, C, dt,
                                                                       pml)
        dt = _inject_step(dt, system if explicit else None)
    how = (f"transient.dt = {dt:g} s" if case["transient.dt"] > 0
           else f"the automatic step {dt:.3g} s")
    # rank 0 holds the histories; its verdict holds for all ranks (no rank may stop alone)
    nt = on_root(lambda: check_run_size(case, run, dt, how, run["wheel_rail"].size,
                                        0 if vehicle is None else vehicle.n_dof,
                                        len(probe_points(mesh, case)[0]), rails.x.shape[0],
                                        rails.n_nodes), comm)
    times = np.arange(nt + 1) * dt
    x = run["x_start"] + run["offsets"][None, :] + run["speeds"][None, :] * times[:, None]
    if surface:
        x = x[:, :0]                     # no wheel: the loads' positions are the case's
    steps_out = output_steps(case, dt, nt)
    resolved = on_root(lambda: band_check(case, mesh, dt, rep), comm)
    if case["output.stress_times"]:
        _check_stress_times(case, steps_out * dt)
    scheme_text = (f"generalized-alpha rho_inf = {case['transient.rho_inf']:g}"
                   if engine == "direct" else
                   {"explicit": "central differences (explicit), ",
                    "imex": "implicit-explicit Newmark (Hughes-Liu), "}[engine] + limit)
    rep.info(f"  dt = {dt:.4e} s, {nt} steps to t = {nt * dt:.4f} s, {steps_out.size} output "
             f"steps; {scheme_text}")
    if pml is not None:
        from .pml import pml_memory_warning

        line = pml_memory_warning(problem, nt * dt)
        if line is not None:
            rep.info(line)
    n_wheels = run["wheel_rail"].size
    scheme = None
    if not explicit:
        if engine == "direct":
            K, M, C, cinfo, _, _ = assemble_matrices(ctx, mesh, dofmap, problem, pml)
            layer = pml_layer(ctx, mesh, dofmap, problem, K, pml)
            _inject_damping(C)
            allowed = None                     # unconditionally stable
        with rep.stage("transient: factorization"):
            if engine == "direct":
                scheme = GeneralizedAlpha.from_radius(dt, case["transient.rho_inf"])
                system = TransientSystem(K, M, C, scheme, comm, pml=layer,
                                         extra_gb=_rail_columns_gb(dofmap.n_dofs, n_wheels))
            else:
                from .imex import ImexSystem

                system = ImexSystem(K, M, C, *partition, dt, comm, pml=layer,
                                    extra_gb=lambda rows: _rail_columns_gb(rows, n_wheels))
                scheme = system.scheme
            rep.info(f"  MUMPS Cholesky of K_eff: {system.time_factorization:.2f} s, factor "
                     f"~{system.factor_memory_gb:.2f} GB"
                     + (" (out of core)" if system.out_of_core else "")
                     + (f"; {system.implicit_rows:,} of {dofmap.n_dofs:,} rows implicit"
                        if engine == "imex" else ""))
    driver = columns = prescribed = coupling = None
    forces = run["forces"]
    if surface:
        forces = None
        try:
            prescribed = surface_load(case, mesh, dofmap.index, dt, nt)
        except ValueError as exc:
            raise TransientInputError(f"railvib transient: load.y = {case['load.y']:g}: "
                                      f"{exc}") from None
    elif vehicle is None:
        coupling = WheelCoupling(rails, run["wheel_rail"])

        def prescribed(n: int):
            dofs, coef, _ = coupling.at(x[n])
            return dofs, -coef * forces[:, None]
    else:
        coupling = WheelCoupling(rails, run["wheel_rail"], getattr(vehicle, "conicity", 0.0))
        irregularity = passage_irregularity(case, vehicle, run)
        driver = VehicleDriver(vehicle, coupling, x, irregularity, dt)
        if not explicit:
            columns = RailColumns(system, rails, LOOKAHEAD_NODES)
    if explicit:
        from .explicit import ExplicitSolver

        solver = ExplicitSolver(system, prescribed, driver)
    else:
        solver = DirectSolver(system, prescribed, driver, columns)
    if engine != "direct":
        from ..model.dofmap import rigid_body_modes

        # GAMG's near null space for the static start, when it is solved by CG
        system.near_null = lambda: rigid_body_modes(mesh.points, dofmap, comm.rank)
    names, coords = probe_points(mesh, case)
    return {"mesh": mesh, "mesh_sha": mesh_sha, "problem": problem, "dofmap": dofmap,
            "rails": rails,
            "vehicle": vehicle, "run": run,
            "dt": dt, "nt": nt, "times": times, "x": x, "steps_out": steps_out, "K": K, "M": M,
            "C": C, "damping": cinfo, "system": system, "solver": solver, "driver": driver,
            "columns": columns, "coupling": coupling, "forces": forces,
            "prescribed": prescribed, "n_wheels": n_wheels, "engine": engine,
            "static_start": surface and case["load.start"] == "static",
            "n_dof": 0 if vehicle is None else vehicle.n_dof,
            "probe_names": names, "probe_coords": coords,
            "probe_sampler": PointSampler(mesh, dofmap, comm.rank, coords, names),
            "rail_sampler": RailSampler(rails, dofmap, comm.rank), "scheme": scheme,
            "pml": pml, "allowed_step": allowed, "resolved_up_to_hz": resolved}


def band_check(case: Case, mesh, dt: float, rep: Reporter) -> float:
    """The mesh's dispersion at the stage's own band, ``transient.f_max``, for its mass and
    step (:func:`~railvib_hpc.mesh.dispersion_check.transient_band_check`, and the
    elements-per-wavelength warnings of the mesh check at that band): its lines, and the
    frequency the run resolves at the farthest probe (``transient.f_max`` when it does;
    rank 0). Raises :class:`~railvib_hpc.mesh.dispersion_check.DispersionError` as the
    mesh check does, at ``mesh.max_dispersion_error``."""
    from ..mesh.checks import max_edge_per_soil_part, wavelength_warnings
    from ..mesh.dispersion_check import transient_band_check

    f_max = case["transient.f_max"]
    quality = {"max_edge_per_soil_part": max_edge_per_soil_part(mesh)}
    for line in wavelength_warnings(quality, case, (f_max, "transient.f_max")):
        rep.info(f"warning: {line}")
    found = transient_band_check(quality, case, mesh.probes, dt)
    if found is None:
        return float(f_max)
    rep.info(f"  {found['line']}")
    for line in found["warnings"]:
        rep.info(f"warning: {line}")
    top = found["resolved_up_to_hz"]
    if top < f_max:
        rep.info(f"warning: the results are resolved up to {top:g} Hz at the farthest probe "
                 f"(predicted peak-velocity error <= 5 %), not up to transient.f_max = "
                 f"{f_max:g} Hz: the studies leave out the one-third-octave bands above it")
    return float(top)


def _inject_step(dt: float, system) -> float:
    """The step, times the factor of a ``"step"`` :data:`~.guard.TEST_INJECTION` (the
    explicit engines' test hook: past the pre-checked limit; ``system``: the explicit
    engine's, whose own step follows)."""
    from . import guard

    inject = guard.TEST_INJECTION
    if inject is None or inject.kind != "step":
        return dt
    dt = float(dt * inject.factor)
    if system is not None:
        system.dt = dt
    return dt


def _inject_damping(C) -> None:
    """``C`` times ``-factor`` for a ``"negative_damping"`` :data:`~.guard.TEST_INJECTION`
    (the direct engine's test hook)."""
    from . import guard

    inject = guard.TEST_INJECTION
    if inject is not None and inject.kind == "negative_damping" and C is not None:
        C.scale(-inject.factor)


def make_guard(init: dict, case: Case, state: State):
    """The run's :class:`~.guard.DivergenceGuard`, started from ``state``: the regions of
    this rank's rows (parts and perfectly matched layers), checked every output stride of
    steps at first (collective)."""
    from .guard import DivergenceGuard, dof_regions, node_regions

    mesh, dofmap, system = init["mesh"], init["dofmap"], init["system"]
    layers = []
    if init["pml"] is not None:
        centres = mesh.points[mesh.hexes].mean(axis=1)
        thickness = case["boundary.layer_thickness"]
        for face in init["pml"][0]:
            layers.append((face.face, np.abs(centres[:, face.axis] - face.plane) < thickness))
    region, names = node_regions(mesh, layers)
    r0, r1 = system.r0, system.r1
    rows = dof_regions(region, dofmap.index, r0, r1)
    steps = init["steps_out"]
    stride = int(steps[1] - steps[0]) if steps.size > 1 else init["nt"]
    guard = DivergenceGuard(system, init["solver"], rows, names, mesh.points, dofmap.index,
                            init["dt"], init["engine"], init["allowed_step"], stride)
    guard.start(state)
    return guard


#: Fraction of the ground's Rayleigh speed from which a train's speed is warned about: the
#: dynamic amplification of a track on a half-space grows steeply above about 0.7 c_R
#: (Dieterman & Metrikine 1996; the Ledsgard measurements, Madshus & Kaynia 2000).
NEAR_CRITICAL_SPEED = 0.7


def speed_warning(case: Case, speed: float) -> str:
    """A warning line when ``speed`` is at least :data:`NEAR_CRITICAL_SPEED` of the ground's
    lowest Rayleigh speed (at or above it only with ``vehicle.supercritical``), else ''."""
    from ..site import ground_rayleigh_speeds

    speeds = ground_rayleigh_speeds(case)
    part, c_r = min(speeds.items(), key=lambda kv: kv[1])
    if speed < NEAR_CRITICAL_SPEED * c_r:
        return ""
    what = ("above the ground's Rayleigh speed (accepted by vehicle.supercritical)"
            if speed >= c_r else "near the ground's Rayleigh speed")
    return (f"WARNING: the train's speed {speed:g} m/s is {speed / c_r:.0%} of c_R = "
            f"{c_r:.1f} m/s ({part}): {what}; the response near the track grows steeply "
            "there (the track's critical speed)")


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


def _stats(init, system, solver, t_integration, t_wall, rss, recorder, n_done, comm) -> dict:
    nt = init["nt"]
    stats = {"solver": "transient", "dt": init["dt"], "n_steps": nt, "steps_run": n_done,
             "t_end": nt * init["dt"], "n_dofs": init["dofmap"].n_dofs,
             "n_nodes": init["mesh"].n_nodes, "ranks": comm.size,
             "engine": init["engine"],
             "rho_inf": init["scheme"].rho_inf if init["scheme"] is not None else None,
             "damping": init["damping"],
             "time_integration": t_integration, "time_total": t_wall,
             "steps_per_second": n_done / max(t_integration, 1e-9),
             "time_factorization": system.time_factorization,
             "time_solves": system.time_solves, "time_products": system.time_products,
             "time_contact": solver.time_contact, "solves": system.n_solves,
             "time_pml": getattr(solver, "time_pml", 0.0) + getattr(system, "time_pml", 0.0),
             "pml_elements": (0 if getattr(system, "pml", None) is None
                              else comm.allreduce(system.pml.n_elements)),
             "factor_memory_gb": system.factor_memory_gb, "out_of_core": system.out_of_core,
             "peak_rss_gb_per_rank": rss, "peak_rss_gb_total": float(sum(rss))}
    if init["columns"] is not None:
        stats["rail_columns"] = init["columns"].n_computed
        stats["time_rail_columns"] = init["columns"].time
    if comm.rank == 0 and init["n_wheels"]:
        f = recorder.arrays["contact_force"]
        x = init["x"]
        lo, hi = float(init["rails"].x.min()), float(init["rails"].x.max())
        on = (x >= lo) & (x <= hi)
        stats["static_wheel_load"] = (init["vehicle"].static_wheel_loads().tolist()
                                      if init["vehicle"] is not None else f[0].tolist())
        stats["mean_contact_force"] = [float(f[on[:, j], j].mean()) if on[:, j].any()
                                       else math.nan for j in range(f.shape[1])]
        stats["peak_contact_force"] = f.max(axis=0).tolist()
        stats["min_contact_force"] = f.min(axis=0).tolist()
        stats["loss_of_contact_steps"] = (int(np.any(f <= 0.0, axis=1)[1:].sum())
                                          if init["vehicle"] is not None else 0)
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


def _write_probes(out_dir: Path, init: dict, recorder: Recorder, case: Case,
                  prov: dict) -> None:
    """probes.h5 + probes/*.csv (layout of reconstruct, with the probes' roles) and the rail
    bending moments (rank 0)."""
    from ..fem.beam import shear_deformation_factors
    from ..io.formats.probes import write_probes_csv, write_probes_h5
    from ..reconstruct.stress import rail_bending_moment, rail_section
    from ..schema import DEFAULT_PROBE_ROLE

    t = init["times"]
    pr = recorder.arrays["probes"]
    hist = {}
    sampler = init["probe_sampler"]
    mesh = init["mesh"]
    user_roles = list(case["output.probe_roles"])
    lines = line_probes(case)
    for i, name in enumerate(init["probe_names"]):
        if name in mesh.probes:
            role = mesh.probe_roles.get(name, DEFAULT_PROBE_ROLE)
        elif name in lines:
            role = "free_field"
        else:
            k = int(name.rsplit("_", 1)[1]) - 1
            role = user_roles[k] if k < len(user_roles) else DEFAULT_PROBE_ROLE
        hist[name] = {"t": t, "displacement": pr[:, 0, i], "velocity": pr[:, 1, i],
                      "acceleration": pr[:, 2, i], "coords": init["probe_coords"][i],
                      "element": np.int64(sampler.elem[i]), "xi": sampler.xi[i],
                      "role": role}
    attrs = {**prov, "solver": "transient"}
    rails = init["rails"]
    if not rails.nodes.shape[0]:             # no track (track.count = 0): no rail group
        write_probes_h5(out_dir / PROBES_H5, hist, attrs=attrs, groups={})
        write_probes_csv(out_dir / PROBES_CSV_DIR, hist)
        return
    sec = rail_section(init["problem"])
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


def _write_histories(path: Path, case: Case, init: dict, recorder: Recorder, stats: dict,
                     prov: dict) -> None:
    """``transient.h5`` (rank 0; checked, atomic, recorded) of the run's recorder and setup
    (:func:`~railvib_hpc.io.formats.transient.write_transient_h5`)."""
    a = recorder.arrays
    vehicle = init["vehicle"]
    context = _checks_context(case)
    write_transient_h5(path, stats=stats, provenance=prov,
                       check=lambda tmp: check_transient(tmp, True, context),
                       time=init["times"], wheel_x=init["x"],
                       rail_index=init["run"]["wheel_rail"],
                       histories={k: v for k, v in a.items() if k not in ("probes", "rail")},
                       dof_names=list(vehicle.dof_names) if vehicle is not None else [],
                       vehicle_type=("surface_load" if uses_surface_load(case)
                                     else case["vehicle.type"]), rail_x=init["rails"].x,
                       rail=a["rail"])


def _rail_columns_gb(rows: int, n_wheels: int) -> float:
    """Memory of the rail columns (:class:`~.integrate.RailColumns`) at most [GB], on
    ``rows`` rows: every DOF for the direct engine, the implicit rows for the IMEX engine
    (its columns are zero elsewhere)."""
    return 8.0 * rows * 4 * 2 * (LOOKAHEAD_NODES + 3) * n_wheels / 1e9


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
