"""The setup of a ``transient`` run: the model, the loads, the step and the engine, as one
typed object (:class:`TransientRun`) that the stage's loop steps, records and
checkpoints (:func:`~.stage.compute`).

:func:`setup_run` (collective) reads the mesh the runner hands over, numbers the DOFs,
checks the layers, builds the passage (rails, vehicle or surface loads), the engine
(:func:`~.engine.build_engine`, declared in :data:`railvib_hpc.time_engines.ENGINES`) and
its step, refuses a run that is too long (:func:`check_run_size`), checks the band the
mesh resolves (:func:`band_check`), factors, and makes the loads and the samplers.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Case
from ..errors import ResourceError
from ..io.stage_protocol import StageContext
from ..log import Reporter
from ..parallel import on_root
from ..problem import Problem
from ..resources import check_memory
from ..site import line_probes
from .engine import Engine, EngineModel, build_engine, engine_class
from .engines import TransientInputError, check_implicit_outside_layers
from .integrate import VehicleDriver
from .output import PointSampler, RailSampler
from .rail import RailDofs, WheelCoupling
from .scheme import choose_time_step, coarse_step_warning
from .surface_case import (
    element_time,
    no_rails,
    surface_load,
    surface_passage,
    uses_surface_load,
)

#: Largest number of time steps of one run: 100 times the thesis passage's 1840 steps,
#: about 7.5 hours at the 7.4 steps/s measured for the thesis model on 2 ranks
#: (docs/transient.md). Checked before anything is built or allocated
#: (:func:`check_run_size`).
MAX_TRANSIENT_STEPS = 200_000
#: Copies of rank 0's histories held at once at the end of a run (the histories and the
#: rail bending moments and file buffers computed from them while the files are written).
HISTORY_COPIES = 2



def check_stress_times(case: Case, t_out: np.ndarray) -> None:
    times = [float(v) for v in case["output.stress_times"]]
    tol = 1e-9 * max(1.0, float(np.abs(t_out).max()))
    bad = [v for v in times if v < t_out[0] - tol or v > t_out[-1] + tol]
    if bad:
        raise TransientInputError(f"output.stress_times = {times}: {bad} outside the stored "
                                  f"time range [{t_out[0]:.6g}, {t_out[-1]:.6g}] s of "
                                  "fields.h5 (output.window)")


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



@dataclass
class TransientRun:
    """Everything the stage's loop needs of a run (:func:`setup_run`; collective).

    Attributes
    ----------
    mesh, mesh_sha, problem, dofmap
        The model (``mesh_sha``: the digest of ``mesh.h5``, rank 0).
    rails, vehicle, passage
        The flexible rails, the vehicle (None: moving forces or surface loads) and the
        passage (:func:`~railvib_hpc.mbs.case_vehicle.passage`).
    engine
        The time-domain engine (:class:`~.engine.Engine`), built and factored.
    dt, nt, times, x, steps_out
        The step, the steps, their times, the wheels' positions per step and the steps
        written to ``fields.h5``.
    driver, coupling, forces, prescribed
        The vehicle's driver, the wheels' coupling, the moving forces [N] and
        ``prescribed(n) -> (dofs, values)`` (None where they do not apply).
    n_wheels, n_dof, static_start
        Wheels (or loads), vehicle DOFs, and whether the soil starts in static
        equilibrium (``load.start = 'static'``).
    probe_names, probe_coords, probe_sampler, rail_sampler
        The probes and the samplers of the probes and the rails.
    pml
        The layers' :func:`~.pml.pml_geometry` (None without ``pml`` faces).
    resolved_up_to_hz
        The frequency the run resolves at the farthest probe (:func:`band_check`).
    """

    mesh: Any
    mesh_sha: str
    problem: Problem
    dofmap: Any
    rails: RailDofs
    vehicle: Any
    passage: dict
    engine: Engine
    dt: float
    nt: int
    times: np.ndarray
    x: np.ndarray
    steps_out: np.ndarray
    driver: VehicleDriver | None
    coupling: WheelCoupling | None
    forces: np.ndarray | None
    prescribed: Any
    n_wheels: int
    n_dof: int
    static_start: bool
    probe_names: list
    probe_coords: np.ndarray
    probe_sampler: PointSampler
    rail_sampler: RailSampler
    pml: tuple | None
    resolved_up_to_hz: float

    # the engine's parts, by the names the loop and the scripts use
    @property
    def system(self):
        return self.engine.system

    @property
    def solver(self):
        return self.engine.solver

    @property
    def K(self):
        return self.engine.K

    @property
    def M(self):
        return self.engine.M

    @property
    def C(self):
        return self.engine.C

    @property
    def columns(self):
        return self.engine.columns

    def __getitem__(self, name: str):
        """``run["system"]``: the attribute ``name`` (scripts written for the setup's
        dictionary keep working)."""
        try:
            return getattr(self, name)
        except AttributeError:
            raise KeyError(name) from None


def setup_run(ctx: StageContext) -> TransientRun:
    """Mesh, DOFs, loads, engine and its step, factor, samplers (collective)."""
    from .pml import pml_faces, pml_geometry

    case, comm, rep = ctx.case, ctx.comm, ctx.rep
    with rep.stage("transient: mesh"):
        mesh, mesh_sha = on_root(lambda: _mesh_input(ctx), comm)
    with rep.stage("transient: dofs"):
        problem, dofmap = _dofs(ctx, mesh)
        # the layers' faces and elements, checked once (a layer the mesh cannot carry is
        # refused before assembly); assembly and the layer's kernel take them from here
        pml = pml_geometry(mesh, problem) if pml_faces(problem) else None
        if pml is not None and engine_class(case["transient.engine"]).implicit_parts:
            check_implicit_outside_layers(case, mesh, pml[1])
        _support_warning(mesh, problem, rep)
    surface = uses_surface_load(case)     # track.count = 0: [load] on the bare soil
    rails, vehicle, run = _passage(case, mesh, dofmap)
    speed = float(np.max(np.abs(run["speeds"])))
    critical = speed_warning(case, speed)
    if critical:
        rep.info(critical)
    crossing = (element_time(mesh, speed) if surface
                else float(np.diff(rails.x, axis=1).min()) / speed)
    engine = build_engine(case["transient.engine"],
                          EngineModel(ctx, mesh, dofmap, problem, rails, vehicle, pml))
    try:
        return _finish(ctx, engine, mesh, mesh_sha, dofmap, rails, vehicle, run, pml,
                       time_step(case, crossing, rep))
    except BaseException:
        engine.destroy()
        raise


def _finish(ctx: StageContext, engine: Engine, mesh, mesh_sha: str, dofmap, rails, vehicle,
            run: dict, pml, dt_band: float) -> TransientRun:
    """:func:`setup_run` from the engine on: its step, the run's size, the band, the
    factor, the loads and the samplers."""
    case, comm, rep = ctx.case, ctx.comm, ctx.rep
    surface = uses_surface_load(case)
    dt = engine.stable_step(dt_band)
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
        check_stress_times(case, steps_out * dt)
    rep.info(f"  dt = {dt:.4e} s, {nt} steps to t = {nt * dt:.4f} s, {steps_out.size} output "
             f"steps; {engine.describe()}")
    if pml is not None:
        from .pml import pml_memory_warning

        line = pml_memory_warning(engine.model.problem, nt * dt)
        if line is not None:
            rep.info(line)
    n_wheels = run["wheel_rail"].size
    engine.factor(n_wheels)
    driver, coupling, forces, prescribed = _loads(case, mesh, dofmap, rails, vehicle, run, x,
                                                  dt, nt)
    engine.make_solver(prescribed, driver)
    names, coords = probe_points(mesh, case)
    return TransientRun(
        mesh=mesh, mesh_sha=mesh_sha, problem=engine.model.problem, dofmap=dofmap,
        rails=rails, vehicle=vehicle, passage=run, engine=engine, dt=dt, nt=nt, times=times,
        x=x, steps_out=steps_out, driver=driver, coupling=coupling, forces=forces,
        prescribed=prescribed, n_wheels=n_wheels,
        n_dof=0 if vehicle is None else vehicle.n_dof,
        static_start=surface and case["load.start"] == "static", probe_names=names,
        probe_coords=coords, probe_sampler=PointSampler(mesh, dofmap, comm.rank, coords,
                                                        names),
        rail_sampler=RailSampler(rails, dofmap, comm.rank), pml=pml,
        resolved_up_to_hz=resolved)


def _dofs(ctx: StageContext, mesh) -> tuple:
    """The run's problem and DOF map, with their log lines (collective)."""
    from ..model.boundary import boundary_summary, layer_line, problem_dofmap

    case, comm, rep = ctx.case, ctx.comm, ctx.rep
    problem = Problem.from_case(case)
    dofmap = problem_dofmap(mesh, problem, comm.size)
    rep.info(f"  {mesh.n_nodes} nodes, {dofmap.n_dofs} free DOFs on {comm.size} rank(s); "
             "faces: " + ", ".join(f"{k} {v['type']}" for k, v in
                                   boundary_summary(mesh, problem).items()))
    layers = layer_line(mesh, problem)
    if layers:
        rep.info(f"  {layers}")
    return problem, dofmap


def _support_warning(mesh, problem: Problem, rep: Reporter) -> None:
    from ..model.boundary import support_warning

    unsupported = support_warning(mesh, problem)
    if unsupported:
        rep.info(unsupported)


def _loads(case: Case, mesh, dofmap, rails: RailDofs, vehicle, run: dict, x: np.ndarray,
           dt: float, nt: int) -> tuple:
    """``(driver, coupling, forces, prescribed)`` of the run: the surface loads, the moving
    forces or the vehicle (None where they do not apply)."""
    from ..mbs.case_vehicle import passage_irregularity

    driver = prescribed = coupling = None
    forces = run["forces"]
    if uses_surface_load(case):
        try:
            prescribed = surface_load(case, mesh, dofmap.index, dt, nt)
        except ValueError as exc:
            raise TransientInputError(f"railvib transient: load.y = {case['load.y']:g}: "
                                      f"{exc}") from None
        return None, None, None, prescribed
    if vehicle is None:
        coupling = WheelCoupling(rails, run["wheel_rail"])

        def prescribed(n: int):
            dofs, coef, _ = coupling.at(x[n])
            return dofs, -coef * forces[:, None]

        return None, coupling, forces, prescribed
    coupling = WheelCoupling(rails, run["wheel_rail"], getattr(vehicle, "conicity", 0.0))
    irregularity = passage_irregularity(case, vehicle, run)
    driver = VehicleDriver(vehicle, coupling, x, irregularity, dt)
    return driver, coupling, forces, prescribed

