"""The ``mbs`` stage: modes.h5 -> vehicle rolling over the flexible track (rank 0) -> mbs.h5.

Everything runs on rank 0 (numpy only); the other ranks wait for the summary
(or the error) broadcast at the end. Output ``mbs.h5`` (written to a temporary
name, renamed when complete, reused when its inputs are unchanged; writer and reader in
:mod:`railvib_hpc.io.formats.mbs`):

* ``/time`` (nt,) [s];
* ``/wheels/x``, ``contact_force`` (positive: wheel pushes the rail down),
  ``penetration``, ``rail_displacement`` (under the wheel along the contact
  normal, ``w + lambda v`` for coned wheels, up positive),
  ``wheel_height`` (the wheel's contact point, ``B^T y``), ``rail_index``
  (n_wheels,), all (nt, n_wheels);
* ``/vehicle/y``, ``y_dot``, ``y_ddot`` (nt, n_dof), attribute ``dof_names``;
* ``/modal/q``, ``q_dot``, ``q_ddot`` (nt, m), ``omega``, ``zeta`` (m,); with
  ``modal.damping = 'full'`` also ``damping_matrix`` (m, m) (``zeta`` is then its diagonal
  as ratios, ``D_ii / (2 omega_i)``);
* ``/static/g``, ``g_dot``, ``g_ddot`` (nt, n_r) and ``/static/q_shift``,
  ``q_shift_dot``, ``q_shift_ddot`` (nt, m) ``= -Lambda^-1 Phi_r^T g`` (and
  derivatives) when the static correction is on (attributes ``basis_file``,
  ``basis``): the fields are ``Phi (q + q_shift) + X g``. The static correction runs the
  kept modes together with the residual modes of
  :func:`.static_correction.residual_modes` (mass, damping and the exact static
  flexibility); ``g = V p`` from their coordinates ``p`` (``/static/residual_omega``,
  ``residual_vectors``), so ``g_dot`` and ``g_ddot`` are exact, not differenced;
* the provenance attributes of :func:`railvib_hpc.io.provenance.provenance`
  (``inputs_sha256``, ``upstream_sha256`` of ``modes.h5``/``static.h5``, ``case_toml``,
  ...), ``complete`` and ``stats`` (JSON: time step, steps, wall time, contact-force
  summary).

Before it integrates, the stage verifies its inputs, the ``modal`` stage's products it
needs (``ctx.input("modal")``: ``modes.h5``, ``static.h5``, ``modal_damping.h5`` as the
case uses them, current for the case, unchanged, sound; otherwise it refuses naming the
file and what differs),
checks that the passage is not empty, that the number of steps stays below
:data:`MAX_MBS_STEPS` and that the histories fit in memory. The computed histories pass
the data checks of :func:`railvib_hpc.io.formats.mbs.check_mbs_arrays` before they are
written.

PNG plots next to it: ``mbs_contact_force.png`` (force vs position),
``mbs_wheel_displacement.png`` and ``mbs_rail_deflection.png``.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..errors import DataError, ResourceError
from ..io.atomic import atomic_file, ensure_space
from ..io.files import MBS_H5, MODAL_DAMPING_H5, MODES_H5, STATIC_H5
from ..io.formats.mbs import MbsStatic, check_mbs, check_mbs_arrays, rail_amplitude, write_mbs_h5
from ..io.formats.static import read_rail_statics
from ..io.products import Selection, StageFile
from ..io.stage_outputs import PassageOutput
from ..io.stage_protocol import Stage, StageContext, StageRunner
from ..log import Reporter
from ..modal.refusals import needs_track
from ..parallel import on_root
from ..resources import check_memory
from .case_vehicle import (
    MBSInputError,
    build_vehicle,
    passage,
    passage_irregularity,
    static_wheel_load,
    two_trains,
)
from .damping_model import modal_damping, residual_damping

if TYPE_CHECKING:
    from mpi4py import MPI

#: Largest number of time steps of one passage: about 2 h at the 14,000 steps/s measured
#: for the thesis wheelset (bench/mbs_thesis_bench.py), 9 h for a 4-car train.
MAX_MBS_STEPS = 100_000_000


def _read_static(out_dir: Path, n_r: int) -> tuple[np.ndarray, np.ndarray]:
    """``K^-1`` on the rail DOFs and the deflated static fields' mass from ``static.h5``."""
    path = out_dir / STATIC_H5
    x_rr, x_mass = read_rail_statics(path)
    if x_rr.shape != (n_r, n_r):
        raise MBSInputError(f"{path}: rail_flexibility has shape {x_rr.shape}, expected "
                            f"({n_r}, {n_r})")
    return x_rr, x_mass


def check_context(case: Case, out_dir: Path) -> dict:
    """What the data check of ``mbs.h5`` needs (see
    :func:`railvib_hpc.io.formats.mbs.check_mbs`)."""
    return {"static_wheel_load": static_wheel_load(case), "modes_path": out_dir / MODES_H5}


def input_files(case: Case) -> tuple[str, ...]:
    """The stage files ``mbs.h5`` is computed from."""
    return ((MODES_H5,) + ((STATIC_H5,) if case["mbs.static_correction"] else ())
            + ((MODAL_DAMPING_H5,) if case["modal.damping"] == "full" else ()))


def verify_inputs(ctx: StageContext) -> dict[str, str]:
    """Verify ``modes.h5`` (and ``static.h5``, ``modal_damping.h5``), the ``modal`` stage's
    products, for the context's case (rank 0; ``ctx.input("modal")``); returns their
    digests.

    Raises
    ------
    StaleInputError, MBSInputError
        Naming the file that is missing, stale or corrupt and the command to run.
    """
    case, out_dir = ctx.case, ctx.out_dir
    if case["mbs.static_correction"] and (out_dir / MODES_H5).exists() \
            and not (out_dir / STATIC_H5).exists():
        raise MBSInputError(f"mbs.static_correction = true needs {out_dir / STATIC_H5}: "
                            "run 'railvib modal' with mbs.static_correction = true first")
    if case["modal.damping"] == "full" and (out_dir / MODES_H5).exists() \
            and not (out_dir / MODAL_DAMPING_H5).exists():
        raise MBSInputError(f"modal.damping = 'full' needs {out_dir / MODAL_DAMPING_H5}: "
                            "run 'railvib modal' with modal.damping = 'full' first")
    return dict(ctx.input("modal", input_files(case)).digests)


def _passage_checks(case: Case, rm, vehicle, t_end: float, x_end: float, m: int,
                    n_wheels: int, n_r: int, out_dir: Path, run_modes) -> float:
    """An empty passage, too many steps or too little memory: one clear error first.
    Returns the time step (``mbs.dt`` or the automatic one)."""
    from .results import kept_steps

    if t_end <= 0:
        raise MBSInputError(
            f"vehicle.x_start = {case['vehicle.x_start']:g} m: the passage ends at x = "
            f"{x_end:g} m (vehicle.x_end, 0 = the end of the rigid exit rail), so the vehicle "
            "has nowhere to go; x_start must lie before the end")
    if case["mbs.dt"]:
        dt, how = case["mbs.dt"], f"mbs.dt = {case['mbs.dt']:g} s"
    else:
        dt = _auto_step(case, rm, run_modes, vehicle)
        how = f"the automatic step {dt:.3g} s"
    nt = int(np.ceil(t_end / dt))
    if nt > MAX_MBS_STEPS:
        raise ResourceError(
            f"the passage takes {t_end:.4g} s (vehicle.t_after = {case['vehicle.t_after']:g} s "
            f"after the last wheel leaves) in steps of {how}: {nt:.3g} steps, more than the "
            f"limit of {MAX_MBS_STEPS:.0e} (about 2 hours); shorten vehicle.t_after or use a "
            "larger mbs.dt (0 = automatic)")
    kept = kept_steps(nt, case["mbs.store_every"]).size
    n_dof = getattr(vehicle, "n_dof", 0) if vehicle is not None else 0
    # positions and shape functions of every step (1 + 5 values per wheel); the stored
    # histories twice (the result and the file being written)
    need = 8.0 * (nt + 1) * (1 + 6 * n_wheels) \
        + 2 * 8.0 * kept * (3 * run_modes.omega.size + 4 * n_wheels + 3 * n_dof + 3 * n_r
                            + 3 * m * (n_r > 0))
    check_memory(need, f"the multibody run ({nt:.3g} steps, {kept:.3g} stored)",
                 "shorten vehicle.t_after, use a larger mbs.dt or mbs.store_every")
    ensure_space(out_dir, need / 2, f"mbs.h5 ({kept:.3g} stored steps)")
    return dt


def simulate_case(ctx: StageContext) -> dict:
    """Run the multibody simulation of the context's case on this process (rank 0, numpy);
    write mbs.h5 + plots.

    Parameters
    ----------
    ctx
        The stage's context (the runner's): the validated case, the folder with
        ``modes.h5`` (and ``static.h5`` for the static correction), the reporter. From a
        script: :func:`run_mbs_stage`.

    Returns
    -------
    dict
        Summary (see ``stats`` in the module notes) with ``reused`` set when an
        existing complete ``mbs.h5`` with the same inputs was kept.
    """
    import h5py

    from .integrate import simulate_moving_force, simulate_vehicle
    from .modal_input import read_rail_modes
    from .static_correction import rail_dof_rows

    case, out_dir, rep = ctx.case, ctx.out_dir, ctx.rep
    modes_path = out_dir / MODES_H5
    upstream = verify_inputs(ctx)
    with h5py.File(modes_path, "r") as f:
        m_file = f["modes/eigenvalue"].shape[0]
    m = case["mbs.n_modes"] or m_file
    if m > m_file:
        raise MBSInputError(f"mbs.n_modes = {m}: {modes_path} has only {m_file} modes")
    path = out_dir / MBS_H5
    context = check_context(case, out_dir)
    old = ctx.reuse(MBS_H5, path=path, why="same modes, vehicle and settings", context=context)
    if old.ok:
        return {**json.loads(old.verdict.attrs.get("stats", "{}")), "reused": True}

    t0 = time.perf_counter()
    rm = read_rail_modes(modes_path, m)
    zeta = modal_damping(case, m, modes_path, ctx)
    vehicle = build_vehicle(case)
    run = passage(case, vehicle, float(max(r.x_nodes[-1] for r in rm.rails)))
    forces, offsets, wheel_rail = run["forces"], run["offsets"], run["wheel_rail"]
    x_start, x_end, t_end = run["x_start"], run["x_end"], run["t_end"]
    speeds = run["speeds"]
    travel = x_end - x_start - float(np.min(offsets[speeds > 0], initial=0.0))
    n_r = rail_dof_rows(rm.rails).shape[1] if case["mbs.static_correction"] else 0
    res, run_modes, run_damping = None, rm, zeta
    if case["mbs.static_correction"]:
        res, run_modes, run_damping = _with_residual_modes(ctx, rm, zeta, n_r)
        rep.info(f"static correction: {res.omega.size} residual modes, "
                 f"{res.omega[0] / (2 * np.pi) if res.omega.size else 0:.1f} - "
                 f"{res.omega[-1] / (2 * np.pi) if res.omega.size else 0:.4g} Hz, added to "
                 f"the {m} modes")
    dt = _passage_checks(case, rm, vehicle, t_end if travel > 0 else 0.0, x_end, m,
                         len(offsets), n_r, out_dir, run_modes)
    t_read = time.perf_counter() - t0
    t_run = time.perf_counter()
    label = "mbs: time integration"

    last = [t_run]

    def progress(n: int, nt: int) -> None:
        now = time.perf_counter()
        if now - last[0] >= 2.0 or n == nt:
            last[0] = now
            rep.progress(label, n, nt, t_run)

    if vehicle is None:
        result = simulate_moving_force(
            run_modes.omega, run_damping, tuple(run_modes.rails[i] for i in wheel_rail),
            forces, x_start + offsets, speeds, t_end, dt=dt,
            store_every=case["mbs.store_every"])
    else:
        irregularity = passage_irregularity(case, vehicle, run)
        rails = run_modes.normal_rails(vehicle.conicity)
        result = simulate_vehicle(
            run_modes.omega, run_damping, rails, vehicle, x_start, speeds, t_end, dt=dt,
            irregularity=irregularity, store_every=case["mbs.store_every"],
            points_per_period=case["mbs.points_per_period"],
            progress=progress, drop_height=case["vehicle.drop_height"])
    wall = time.perf_counter() - t_run
    static = None
    if res is not None:
        result, static = _split_residual(result, res, m)
        zeta = run_damping[:m, :m] if np.ndim(run_damping) == 2 else run_damping[:m]
    stats = _summary(result, rm.rails, vehicle, wall, t_read, m)
    stats["static_correction"] = res is not None
    if res is not None:
        stats["residual_modes"] = int(res.omega.size)
    rep.info(format_summary(stats))
    problems = check_mbs_arrays(result.t, result.contact_force, result.q, result.q_dot,
                                result.q_ddot, rm.omega, context["static_wheel_load"],
                                rail_amplitude(modes_path, m))
    if problems:
        raise DataError(f"the multibody results fail their data checks ({problems[0]}); "
                        f"{path} was not written. Check the vehicle, irregularity and mbs "
                        "settings")
    attrs = ctx.provenance(MBS_H5, upstream)
    attrs["stats"] = json.dumps(stats)
    write_mbs_h5(path, result, attrs=attrs, check=lambda tmp: check_mbs(tmp, True, context),
                 rail_index=wheel_rail,
                 wheel_height=None if vehicle is None else result.y @ vehicle.contact_matrix(),
                 vehicle_type=case["vehicle.type"], omega=rm.omega, zeta=zeta,
                 static=None if static is None else _mbs_static(static, rm, res))
    rep.info(f"wrote {path}")
    plots = write_plots(out_dir, result, vehicle)
    rep.info("wrote " + ", ".join(str(p) for p in plots))
    return {**stats, "reused": False}


def _with_residual_modes(ctx: StageContext, rm, zeta, n_r: int):
    """The residual modes of the static correction, the rail modes with them appended
    and the damping of both (:mod:`.static_correction`)."""
    import h5py

    case, out_dir = ctx.case, ctx.out_dir
    from .modal_input import RailModes, read_rail_modes
    from .static_correction import kept_residual_mass, rail_dof_rows, residual_modes

    x_rr, mass_file = _read_static(out_dir, n_r)
    m = rm.omega.size
    with h5py.File(out_dir / MODES_H5, "r") as f:
        m_file = f["modes/eigenvalue"].shape[0]
    rest_rows, omega_rest = np.zeros((0, n_r)), np.zeros(0)
    if m_file > m:                                        # the rail rows of the modes not kept
        every = read_rail_modes(out_dir / MODES_H5)
        rest_rows, omega_rest = rail_dof_rows(every.rails)[m:], every.omega[m:]
    res = residual_modes(x_rr, kept_residual_mass(mass_file, rest_rows, omega_rest),
                         rm.rails, rm.omega)
    k = res.omega.size
    rails = res.rails(rm.rails)
    lateral = tuple((np.vstack([pv, np.zeros((k, pv.shape[1]))]),
                     np.vstack([prz, np.zeros((k, prz.shape[1]))])) for pv, prz in rm.lateral)
    modes = RailModes(np.concatenate([rm.omega, res.omega]), tuple(rails), rm.rail_y,
                      rm.rail_z, lateral)
    return res, modes, residual_damping(case, zeta, res, rest_rows, rm.omega, omega_rest,
                                        out_dir / MODES_H5, ctx)


def _auto_step(case: Case, rm, run_modes, vehicle) -> float:
    """The automatic time step: the kept modes' band (residual modes respond
    quasi-statically in the exact propagator) and the contact resonance against the rails
    the vehicle runs on (residual modes included), shortened to divide ``output.dt``."""
    from .integrate import auto_time_step, wheel_rails

    if vehicle is None:
        dt = auto_time_step(rm.omega)
    else:
        rails = run_modes.normal_rails(getattr(vehicle, "conicity", 0.0))
        dt = auto_time_step(rm.omega, wheel_rails(rails, vehicle), vehicle,
                            case["mbs.points_per_period"],
                            max(case["vehicle.speed"], case["train2.speed"] if two_trains(case)
                                else 0.0))
    out = case["output.dt"]
    # shortened to a whole fraction of output.dt, so the fields come at the times asked for
    return out / np.ceil(out / dt * (1.0 - 1e-12)) if out > 0 else dt


def _split_residual(result, res, m: int):
    """The kept modes' histories, and ``g = V p`` with its exact derivatives from the
    residual modes' coordinates ``p``."""
    import dataclasses

    v = res.vectors.T
    static = (result.q[:, m:] @ v, result.q_dot[:, m:] @ v, result.q_ddot[:, m:] @ v)
    kept = dataclasses.replace(result, q=np.ascontiguousarray(result.q[:, :m]),
                               q_dot=np.ascontiguousarray(result.q_dot[:, :m]),
                               q_ddot=np.ascontiguousarray(result.q_ddot[:, :m]),
                               rail_loads=static[0])
    return kept, static


def _on_flexible(result, rails) -> np.ndarray:
    """(nt, n_wheels) True where the wheel is on the flexible rail."""
    lo = min(r.x_nodes[0] for r in rails)
    hi = max(r.x_nodes[-1] for r in rails)
    return (result.x >= lo) & (result.x <= hi)


def _summary(result, rails, vehicle, wall: float, t_read: float, m: int) -> dict:
    on = _on_flexible(result, rails)
    f = result.contact_force
    mean = [float(f[on[:, j], j].mean()) if on[:, j].any() else float("nan")
            for j in range(f.shape[1])]
    peak = [float(f[:, j].max()) for j in range(f.shape[1])]
    low = [float(f[:, j].min()) for j in range(f.shape[1])]
    static = (vehicle.static_wheel_loads().tolist() if vehicle is not None
              else f[0].tolist())
    return {
        "n_modes": m, "dt": result.dt, "n_steps": result.n_steps,
        "n_stored": int(result.t.size), "t_end": float(result.t[-1]),
        "time_integration": wall, "time_read": t_read,
        "steps_per_second": result.n_steps / max(wall, 1e-9),
        "static_wheel_load": static, "mean_contact_force": mean, "peak_contact_force": peak,
        "min_contact_force": low,
        "max_rail_deflection": float(-result.rail_displacement.min()),
        "loss_of_contact_steps": int(result.n_loss_of_contact),
        "loss_of_contact_per_wheel": result.loss_of_contact_per_wheel.tolist(),
    }


def format_summary(stats: dict) -> str:
    """Printable table of the contact forces per wheel and the run statistics."""
    lines = [f"mbs: {stats['n_modes']} modes, dt = {stats['dt']:.3e} s, {stats['n_steps']} "
             f"steps in {stats['time_integration']:.2f} s ({stats['steps_per_second']:.0f} "
             "steps/s)",
             "  wheel  static [kN]  mean on flexible rail [kN]  peak [kN]  min [kN]  "
             "steps without contact"]
    for j, (s, mu, pk, lo) in enumerate(zip(stats["static_wheel_load"],
                                            stats["mean_contact_force"],
                                            stats["peak_contact_force"],
                                            stats["min_contact_force"])):
        lost = (stats["loss_of_contact_per_wheel"][j]
                if stats["loss_of_contact_per_wheel"] else 0)
        lines.append(f"  {j:5d}  {s / 1e3:11.3f}  {mu / 1e3:26.3f}  {pk / 1e3:9.3f}  "
                     f"{lo / 1e3:8.3f}  {lost:21d}")
    lines.append(f"  max rail deflection under a wheel: {stats['max_rail_deflection'] * 1e3:.4f}"
                 " mm")
    return "\n".join(lines)


def _mbs_static(static, rm, res) -> MbsStatic:
    """The static correction as ``mbs.h5`` stores it (``g`` and its derivatives, the kept
    modes' rail DOF rows, the residual modes)."""
    from .static_correction import rail_dof_rows

    return MbsStatic(static, rail_dof_rows(rm.rails), res.omega, res.vectors, STATIC_H5)


def write_plots(out_dir: Path, result, vehicle) -> list[Path]:
    """PNG plots: contact force vs position, wheel displacement, rail deflection under wheels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    paths = []
    nw = result.x.shape[1]
    show = range(nw) if nw <= 8 else range(0, nw, max(nw // 8, 1))

    def save(fig, name):
        p = out_dir / name
        with atomic_file(p) as tmp:
            fig.savefig(tmp, dpi=120, format="png")
        plt.close(fig)
        paths.append(p)

    def curves(name, xs, ys, xlabel, ylabel, title, empty=""):
        fig, ax = plt.subplots(figsize=(9, 4.5))
        if ys is None:
            ax.text(0.5, 0.5, empty, ha="center", transform=ax.transAxes)
        else:
            for j in show:
                ax.plot(xs[:, j] if xs.ndim == 2 else xs, ys[:, j], lw=0.8, label=f"wheel {j}")
            ax.legend(fontsize=7, ncol=4)
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(alpha=0.3)
        save(fig, name)

    curves("mbs_contact_force.png", result.x, result.contact_force / 1e3,
           "wheel position x [m]", "contact force [kN]", "Wheel-rail contact force")
    heights = None if vehicle is None else result.y @ vehicle.contact_matrix() * 1e3
    curves("mbs_wheel_displacement.png", result.t, heights, "time [s]",
           "wheel vertical displacement [mm]", "Wheel displacement at the contact points",
           "moving forces: no vehicle")
    curves("mbs_rail_deflection.png", result.x, result.rail_displacement * 1e3,
           "wheel position x [m]", "rail displacement under the wheel [mm]",
           "Rail deflection under the wheels")
    return paths


def compute(ctx: StageContext) -> PassageOutput:
    """``railvib mbs``: rank 0 simulates (see :func:`simulate_case`), every rank gets the
    output."""
    with ctx.rep.stage("mbs"):
        return on_root(lambda: PassageOutput.of_stats(simulate_case(ctx), ctx.out_dir),
                       ctx.comm)


#: The passage's case keys beyond the modes' (``mbs.h5`` extends ``modes.h5``: the mesh,
#: the model and the modal solution, the random fields and the reduced model): the damping
#: (the materials' and pads' ratios, [modal]'s damping settings, [damping]), the vehicle,
#: the irregularity (and its file) and [mbs]; not the modal solver's layout.
MBS_KEYS: Selection = (
    ("materials", ()), ("pads", ()), ("modal.damping", ()), ("modal.damping_ratio", ()),
    ("damping", ()), ("vehicle", ()), ("train2", ()), ("irregularity", ()), ("mbs", ()))
#: ``mbs.h5``: computed from the modes (the static fields and the projected damping when
#: the case uses them).
MBS_FILE = StageFile(MBS_H5, "mbs", 2, MBS_KEYS, (MODES_H5, STATIC_H5, MODAL_DAMPING_H5), (),
                     ("mesh.file", "irregularity.file"), check=check_mbs,
                     extends=(MODES_H5,), check_context=check_context)

STAGE = Stage(name="mbs", help="roll the vehicle over the flexible track in modal coordinates",
              products=(MBS_FILE,), reads=(MODES_H5, STATIC_H5, MODAL_DAMPING_H5),
              compute=compute, needs=("modal",),
              refuse=needs_track)


def run_mbs_stage(case: Case, out_dir: Path, comm: MPI.Comm, rep: Reporter,
                  petsc_options: list[str] | None = None) -> dict:
    """The ``mbs`` stage from a script: :data:`STAGE` through the runner (the folder's
    lock; no ``run.json`` entry). Returns its summary (every rank)."""
    runner = StageRunner(out_dir, comm, rep, petsc_options or (), command="mbs")
    return dict(runner.run(STAGE, case, record=False).result.summary)
