"""``railvib transient`` on a spectral soil (``mesh.order > 1``): the case's bare soil, its
moving surface load, damping and faces as a :class:`~.spectral_system.SpectralSoil`, run by
the explicit engine, written as the trilinear path writes (docs/spectral.md).

What it takes (the rest is refused before meshing, :mod:`.spectral_refusals`): the mesh
stage's hexahedra of the bare soil (``track.count = 0``, ``building.present = false``), all
promoted to order ``mesh.order``; ``damping.model`` ``none`` or ``rayleigh``
(``alpha M + beta K``, the kernel applies ``beta K``); the faces ``fixed``, ``roller``,
``free`` and ``absorbing`` (Lysmer dashpots on the GLL face nodes, and springs with
``boundary.virtual_thickness``); the moving point loads of ``[load]`` (spread along x as
:class:`~.surface_load.MovingSurfaceLoad` spreads them, each point's consistent load the
GLL basis of the element under it), standing in static equilibrium at t = 0 with
``load.start = 'static'`` (CG on the matrix-free operator). The step is
:data:`~.spectral_system.STEP_SAFETY` of the Lanczos bound of the stable step (or ``transient.dt``
when it is below it), bounded by the band's automatic step.

Outputs: ``probes.h5`` + ``probes/*.csv`` (the probes read through the GLL basis at any
point, the layout and roles of the trilinear path's), ``transient.h5`` (no wheel, no rail:
the tables of the bare soil, with the band the mesh resolves at the farthest probe: the
mesh check's GLL relation at ``transient.f_max`` and the run's step,
:func:`~.run_setup.band_check`) and ``fields.h5`` at the hex8 mesh's nodes (the GLL nodes
that are the hexahedra's corners: ``fields.xdmf`` shows the trilinear interpolation of the
spectral field; the inner GLL nodes are not written). No checkpoint is written: an
interrupted run starts again at t = 0.
"""

from __future__ import annotations

import math
import time
import uuid

import numpy as np

from ..io.files import (
    FIELDS_H5,
    MESH_H5,
    PROBES_CSV_DIR,
    PROBES_H5,
    TRANSIENT_CHECKPOINT_H5,
    TRANSIENT_FIELDS,
    TRANSIENT_H5,
    TRANSIENT_PROBES,
)
from ..io.stage_protocol import StageContext
from ..parallel import on_root
from ..problem import Problem
from ..resources import peak_memory_gb
from ..site import line_probes
from .engines import TransientInputError
from .guard import DivergenceGuard
from .output import FieldWriter
from .run_setup import band_check
from .scheme import choose_time_step
from .spectral_output import CornerDofMap, GllSampler, corner_values
from .spectral_system import STEP_SAFETY, FacePlane, SpectralSoil, SpectralState
from .surface_case import run_up_time, surface_passage
from .surface_load import SPREAD_SPACING, SurfaceLoadPath, spreading

__all__ = ["run_spectral_transient", "spectral_soil"]

#: The stage's product names (:data:`railvib_hpc.io.products.STAGE_FILES`).
_FIELDS, _PROBES, _HISTORIES = TRANSIENT_FIELDS, TRANSIENT_PROBES, TRANSIENT_H5
#: Largest number of steps (the trilinear path's :data:`.stage.MAX_TRANSIENT_STEPS`).
MAX_STEPS = 200_000
#: Seconds between two progress lines.
PROGRESS_S = 2.0


def spectral_soil(case, mesh, comm) -> SpectralSoil:
    """The case's bare soil as spectral elements of order ``mesh.order`` (collective)."""
    from ..boundary_registry import boundary_kind
    from ..fem.material import lame_parameters
    from ..model.boundary import FACE_AXIS, face_node_sets, face_types
    from ..model.boundary_kinds.absorbing import material_arrays
    from ..model.damping import problem_rayleigh
    from ..model.dofmap import COMPONENTS

    problem = Problem.from_case(case)
    e, nu, rho = material_arrays(problem, mesh.hex_part)
    lam, mu = lame_parameters(e, nu)
    sets = face_node_sets(mesh)
    faces = []
    for face, kind in face_types(problem).items():
        nodes = sets.get(face, np.zeros(0, np.int64))
        if nodes.size == 0:
            continue
        axis = FACE_AXIS[face]
        coord = mesh.points[nodes, axis]
        if np.ptp(coord) > 1e-9 * max(1.0, float(np.ptp(mesh.points[:, axis]))):
            raise TransientInputError(f"railvib transient: mesh.order = {case['mesh.order']}: "
                                      f"the face {face} is not a plane (the spectral soil's "
                                      "faces are the planes of a box)")
        held = tuple(COMPONENTS.index(c) for c in boundary_kind(kind).constrained(face)
                     if c in COMPONENTS[:3])
        faces.append(FacePlane(face, axis, float(np.median(coord)), held,
                               kind == "absorbing"))
    alpha = beta = 0.0
    if case["damping.model"] == "rayleigh":
        alpha, beta = problem_rayleigh(problem)
    return SpectralSoil(case["mesh.order"], mesh.points, mesh.hexes, lam, mu, rho, faces,
                        case["boundary.virtual_thickness"], alpha, beta, comm)


def _spread_spacing(gll_spacing: float, travel: float) -> float:
    """The spacing of a spread load's points: at most :data:`~.surface_load.SPREAD_SPACING`
    of the mean GLL spacing, and a whole fraction of the load's travel per step.

    A point's nodal shares kink where it crosses an element face; points ``s`` apart pass
    at ``c / s``, which the step samples at ``1 / dt``. At the trilinear path's spacing
    (``SPREAD_SPACING h``: 459 Hz at 0.6 c_R on 2 m elements of order 4, inside the grid's
    band, up to 580 Hz) the receivers rang at 465 Hz; at ``SPREAD_SPACING h / N`` that
    frequency aliased into the band (measured). With ``s = c dt / k`` the points of step
    ``n + 1`` are those of step ``n`` moved by ``k`` places: the same positions, the
    envelope's weights alone change, and nothing passes at a frequency of its own."""
    if travel <= 0:
        return SPREAD_SPACING * gll_spacing
    return travel / math.ceil(travel / (SPREAD_SPACING * gll_spacing))


class SpectralLoad:
    """The moving surface loads on the spectral soil: per step the unassembled nodal loads
    of the points this rank's elements carry (located once for the whole run)."""

    def __init__(self, case, mesh, soil: SpectralSoil, dt: float, nt: int):
        from ..mesh.search import locate

        ld = case["load"]
        run = surface_passage(case)
        path = SurfaceLoadPath(forces=run["forces"], offsets=run["offsets"],
                               x_start=run["x_start"], y=float(ld["y"]),
                               speed=float(ld["speed"]),
                               ramp_time=0.0 if ld["start"] == "static" else float(
                                   ld["ramp_time"]),
                               run_up=run_up_time(case), half_width=float(ld["half_width"]),
                               frequency=float(ld["frequency"]))
        t = np.arange(nt + 1) * dt
        x = path.positions(t)
        edges = np.diff(np.unique(np.round(mesh.points[:, 0], 9)))
        offsets, share = spreading(path.half_width, _spread_spacing(
            float(edges.min()) / soil.order, float(ld["speed"]) * dt))
        xs = (x[:, :, None] + offsets[None, None, :]).reshape(nt + 1, -1)
        z_top = float(case["geometry.z1"])
        height = float(np.ptp(mesh.points[:, 2])) or 1.0
        pts = np.stack([xs.ravel(), np.full(xs.size, path.y),
                        np.full(xs.size, z_top - 1e-9 * height)], axis=1)
        elem, xi = locate(pts, mesh)
        if not (elem >= 0).any():
            raise TransientInputError(f"railvib transient: load.y = {path.y:g}: the loads "
                                      "never stand on the soil surface")
        self.elem = elem.reshape(nt + 1, -1)
        self.xi = xi.reshape(nt + 1, -1, 3)
        self.amp = np.repeat(path.amplitudes(t), offsets.size, axis=1) * np.tile(
            share, x.shape[1])
        self.soil = soil
        self.work = 0.0

    def __call__(self, n: int) -> np.ndarray:
        """The unassembled load of step ``n`` on the local nodes, (n_local, 3)."""
        f = np.zeros((len(self.soil.nodes), 3))
        on = self.elem[n] >= 0
        if on.any():
            force = np.zeros((int(on.sum()), 3))
            force[:, 2] = -self.amp[n][on]                           # downwards
            nodes, values = self.soil.element_load(self.elem[n][on], self.xi[n][on], force)
            np.add.at(f, nodes, values)
        return f


class _GuardSystem:
    """What :class:`~.guard.DivergenceGuard` reads of an engine, on the soil's owned nodes
    (rows: the owned components in the global owned numbering)."""

    def __init__(self, soil: SpectralSoil):
        self.soil, self.comm = soil, soil.comm
        self.m = np.repeat(soil.m[soil.owned], 3)
        self.r0 = int(3 * soil.owned_offsets[soil.comm.rank])
        self.K = None

    def times(self, A, x: np.ndarray) -> np.ndarray:
        full = np.zeros((len(self.soil.nodes), 3))
        full[self.soil.owned] = x.reshape(-1, 3)
        self.soil.assemble(full)                  # the owners' values at every holder
        return self.soil.stiffness_times(full)[self.soil.owned].ravel()


class _GuardView:
    """A state as the guard reads it: the owned rows, flat."""

    def __init__(self, soil: SpectralSoil, st: SpectralState):
        self.step = st.step
        self.u, self.v, self.a = (x[soil.owned].ravel() for x in (st.u, st.v, st.a))


def _time_step(case, soil: SpectralSoil, rep) -> tuple[float, float, str]:
    """``(dt, critical, text)``: the band's step bounded by the stable one."""
    tr = case["transient"]
    critical, omega = soil.stable_step()
    limit = STEP_SAFETY * critical
    if tr["dt"] > 0:
        if tr["dt"] > limit:
            raise TransientInputError(
                f"transient.dt = {tr['dt']:g} s is above the spectral soil's stable step "
                f"{critical:.4g} s x {STEP_SAFETY:g} = {limit:.4g} s (omega_max = "
                f"{omega:.4g} rad/s of order {soil.order}); allowed: 0 (automatic) or "
                f"<= {limit:.4g} s")
        dt = tr["dt"]
    else:
        dt = min(limit, choose_time_step(tr["f_max"], tr["steps_per_period"],
                                         case["output.dt"]))
    soil.dt_critical = critical
    text = (f"central differences (explicit) on spectral elements of order {soil.order}, "
            f"stable step {critical:.4g} s (Lanczos bound, omega_max = {omega:.4g} rad/s)")
    return dt, critical, text


def _output_steps(case, dt: float, nt: int) -> np.ndarray:
    """Steps written to ``fields.h5`` (the trilinear path's rule: every ``output.dt``
    within ``output.window``)."""
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


def _probe_points(mesh, case) -> tuple[list[str], np.ndarray, list[str]]:
    """Names, coordinates and roles (the trilinear path's order and roles)."""
    from ..schema import DEFAULT_PROBE_ROLE

    names = list(mesh.probes)
    coords = [mesh.probes[k] for k in names]
    roles = [mesh.probe_roles.get(k, DEFAULT_PROBE_ROLE) for k in names]
    user_roles = list(case["output.probe_roles"])
    for i, p in enumerate(np.asarray(case["output.probes"], dtype=float).reshape(-1, 3)):
        names.append(f"user_{i + 1}")
        coords.append(p)
        roles.append(user_roles[i] if i < len(user_roles) else DEFAULT_PROBE_ROLE)
    for name, point in line_probes(case).items():
        names.append(name)
        coords.append(point.point)
        roles.append("free_field")
    return names, np.asarray(coords, dtype=float).reshape(-1, 3), roles


def _initial_state(case, soil: SpectralSoil, load: SpectralLoad, dt: float, rep):
    """The state at t = 0: at rest, in static equilibrium under the loads with
    ``load.start = 'static'`` (CG), else undeformed with ``a_0 = f_0 / m``."""
    n = len(soil.nodes)
    st = SpectralState(0, np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3)))
    f0 = soil.assemble(load(0))
    if case["load.start"] == "static":
        t0 = time.perf_counter()
        try:
            st.u, iterations = soil.static_solve(f0)
        except RuntimeError as exc:
            raise TransientInputError(f"railvib transient: load.start = 'static': {exc} "
                                      "(boundary.virtual_thickness > 0 holds absorbing faces "
                                      "statically)") from None
        rep.info(f"  static start: CG with the diagonal of K, {iterations} iterations, "
                 f"{time.perf_counter() - t0:.1f} s")
    st.a = soil.acceleration(st.u, st.v, load(0), dt)
    return st


def run_spectral_transient(ctx: StageContext) -> dict:
    """``railvib transient`` of a spectral soil (collective): setup, static start, time
    integration with the divergence guard and progress lines, ``fields.h5``,
    ``probes.h5``, ``transient.h5``. Returns the run statistics."""
    t_wall = time.perf_counter()
    case, comm, rep, out_dir = ctx.case, ctx.comm, ctx.rep, ctx.out_dir
    with rep.stage("transient: mesh"):
        given = ctx.input("mesh")
        mesh, mesh_sha = given.value, given.sha256
    with rep.stage("transient: spectral soil"):
        soil = spectral_soil(case, mesh, comm)
        dt, critical, text = _time_step(case, soil, rep)
        # the mesh's dispersion at transient.f_max on the GLL grid of this order and step
        resolved = on_root(lambda: band_check(case, mesh, dt, rep), comm)
        run = surface_passage(case)
        nt = int(math.ceil(run["t_end"] / dt - 1e-9))
        if nt > MAX_STEPS:
            raise TransientInputError(f"the passage lasts {run['t_end']:.4g} s: {nt:,} steps "
                                      f"of {dt:.3g} s, more than the limit of {MAX_STEPS:,}")
        n_dofs = soil.n_dofs
        rep.info(f"  order {soil.order}: {len(soil.mesh.elements):,} elements, "
                 f"{soil.mesh.n_nodes:,} GLL nodes, {n_dofs:,} free DOFs on {comm.size} "
                 f"rank(s) ({soil.n_interface:,} interface nodes); setup "
                 f"{soil.setup_time:.1f} s")
        rep.info(f"  dt = {dt:.4e} s, {nt} steps to t = {nt * dt:.4f} s; {text}")
        steps_out = _output_steps(case, dt, nt)
        load = SpectralLoad(case, mesh, soil, dt, nt)
        names, coords, roles = _probe_points(mesh, case)
        sampler = GllSampler(mesh, soil, coords, names)
    with rep.stage("transient: initial state"):
        st = _initial_state(case, soil, load, dt, rep)
    stats = _integrate(ctx, mesh, mesh_sha, soil, load, sampler, st, dt, nt, steps_out)
    stats.update({"resolved_up_to_hz": resolved,
                  "time_total": time.perf_counter() - t_wall, "n_dofs": n_dofs,
                  "dt_critical": critical})
    with rep.stage("transient: probes, histories"):
        on_root(lambda: _write_rank0(ctx, mesh_sha, stats, names, coords, roles, sampler,
                                     run, dt, nt), comm)
    rep.info(f"transient: {n_dofs:,} DOFs (spectral, order {soil.order}), dt = {dt:.3e} s, "
             f"{nt} steps in {stats['time_integration']:.1f} s "
             f"({stats['steps_per_second']:.1f} steps/s, {stats['ns_per_dof_step']:.1f} ns per "
             f"DOF and step), peak memory {stats['peak_rss_gb_total']:.2f} GB (all ranks)")
    rep.info(f"wrote {out_dir / FIELDS_H5}, {out_dir / PROBES_H5}, {out_dir / TRANSIENT_H5}")
    return {**stats, "reused": False}


def _integrate(ctx, mesh, mesh_sha, soil, load, sampler, st, dt, nt, steps_out) -> dict:
    """The time loop (collective): probes at every step, fields at the output steps, the
    guard, progress lines; ``fields.h5`` finished. Returns the statistics."""
    case, comm, rep = ctx.case, ctx.comm, ctx.rep
    upstream = {MESH_H5: mesh_sha}
    run_id = on_root(lambda: uuid.uuid4().hex, comm)
    attrs = on_root(lambda: {**ctx.provenance(_FIELDS, upstream), "run_id": run_id,
                             "stride": int(steps_out[1] - steps_out[0])
                             if steps_out.size > 1 else 1, "window": "null"}, comm)
    corner = CornerDofMap(mesh.n_nodes, comm.size)
    writer = FieldWriter(ctx.out_dir / FIELDS_H5, comm, mesh, corner, steps_out * dt,
                         steps_out, case["output.float32"], attrs, block=16)
    out_index = np.full(nt + 1, -1, dtype=np.int64)
    out_index[steps_out] = np.arange(steps_out.size)
    history = np.zeros((nt + 1, 3, sampler.n, 3)) if comm.rank == 0 else None
    guard_system = _GuardSystem(soil)
    guard = DivergenceGuard(guard_system, load, np.zeros(3 * int(soil.owned.sum()), np.int64),
                            ["soil"], soil.owned_points,
                            np.arange(3 * len(soil.owned_points)).reshape(-1, 3), dt,
                            "explicit", soil.dt_critical, max(1, int(
                                steps_out[1] - steps_out[0]) if steps_out.size > 1 else nt))
    guard.start(_GuardView(soil, st))

    def record(n: int) -> None:
        values = sampler.sample(st.u, st.v, st.a)
        if comm.size > 1:
            total = np.zeros_like(values) if comm.rank == 0 else None
            comm.Reduce(values, total, root=0)
            values = total
        if comm.rank == 0:
            history[n] = values
        k = out_index[n]
        if k >= 0 and energies is not None:
            energies.append((n * dt, soil.energy(st, dt)))
        if k >= 0:
            writer.put(int(k), *(corner_values(soil, x, mesh.n_nodes) for x in
                                 (st.u, st.v, st.a)))

    # test hook: the scheme's energy at the output steps (two more products each)
    energies = [] if ctx.options.get("energy_history") else None
    record(0)
    t_run = last = time.perf_counter()
    with rep.stage("transient: time integration"):
        while st.step < nt:
            f_next = load(st.step + 1)
            soil.step(st, f_next, dt)
            # the load's work in the scheme's balance (dt f_n . v_n after the step, the
            # explicit engine's; this rank's element loads)
            load.work += dt * float(np.vdot(f_next, st.v))
            if guard.due(st.step, st.step == nt):
                guard.check(_GuardView(soil, st))
            record(st.step)
            now = time.perf_counter()
            if comm.rank == 0 and (now - last >= PROGRESS_S or st.step == nt):
                last = now
                rep.progress(f"transient: step {st.step}/{nt} (t = {st.step * dt:.4f} s, "
                             f"{st.step / max(now - t_run, 1e-9):.1f} steps/s)", st.step, nt,
                             t_run)
    t_integration = time.perf_counter() - t_run
    with rep.stage("transient: fields"):
        writer.finish(None)
    rep.info(guard.summary(soil.n_dofs))
    rss = comm.allgather(peak_memory_gb())
    n_dofs = soil.n_dofs
    nbytes = comm.allreduce(soil.nbytes) if comm.size > 1 else soil.nbytes
    stats = {"solver": "transient", "dt": dt, "n_steps": nt, "steps_run": nt,
             "t_end": nt * dt, "n_nodes": soil.mesh.n_nodes, "ranks": comm.size,
             "engine": "explicit", "rho_inf": None, "order": soil.order,
             "damping": {"alpha": soil.alpha, "beta": soil.beta},
             "time_integration": t_integration,
             "steps_per_second": nt / max(t_integration, 1e-9),
             "ns_per_dof_step": 1e9 * t_integration * comm.size / max(nt * n_dofs, 1),
             "bytes_per_dof": nbytes / max(n_dofs, 1),
             "node_set_bytes_per_dof": soil.mesh_nbytes * comm.size / max(n_dofs, 1),
             "kernel_ns_per_dof_step": 1e9 * soil.time_products * comm.size
             / max(nt * n_dofs, 1),
             "time_factorization": 0.0, "time_solves": 0.0,
             "time_products": soil.time_products, "time_contact": 0.0, "solves": 0,
             "time_pml": 0.0, "pml_elements": 0, "factor_memory_gb": 0.0,
             "out_of_core": False, "peak_rss_gb_per_rank": rss,
             "peak_rss_gb_total": float(sum(rss)), "guard": guard.stats(n_dofs)}
    if energies is not None:
        stats["energy"] = energies
    stats["history"] = history
    return stats


def _write_rank0(ctx, mesh_sha, stats, names, coords, roles, sampler, run, dt, nt) -> None:
    """``probes.h5``, ``probes/*.csv`` and ``transient.h5`` (rank 0)."""
    from ..io.formats.probes import write_probes_csv, write_probes_h5
    from ..io.formats.transient import check_transient, write_transient_h5
    from .surface_case import no_rails

    upstream = {MESH_H5: mesh_sha}
    history = stats.pop("history")
    t = np.arange(nt + 1) * dt
    hist = {}
    for i, name in enumerate(names):
        hist[name] = {"t": t, "displacement": history[:, 0, i], "velocity": history[:, 1, i],
                      "acceleration": history[:, 2, i], "coords": coords[i],
                      "element": np.int64(sampler.elem[i]), "xi": sampler.xi[i],
                      "role": roles[i]}
    out = ctx.out_dir
    write_probes_h5(out / PROBES_H5, hist, attrs={**ctx.provenance(_PROBES, upstream),
                                                  "solver": "transient"}, groups={})
    write_probes_csv(out / PROBES_CSV_DIR, hist)
    empty = np.zeros((nt + 1, 0))
    rails = no_rails()
    write_transient_h5(out / TRANSIENT_H5, stats=stats,
                       provenance=ctx.provenance(_HISTORIES, upstream),
                       check=lambda tmp: check_transient(tmp, True, {"static_wheel_load": 0.0}),
                       time=t, wheel_x=empty, rail_index=run["wheel_rail"],
                       histories={"contact_force": empty, "penetration": empty,
                                  "rail_displacement": empty, "wheel_height": empty,
                                  "y": empty, "y_dot": empty, "y_ddot": empty},
                       dof_names=[], vehicle_type="surface_load", rail_x=rails.x,
                       rail=np.zeros((nt + 1,) + rails.dofs.shape[:2] + (2,)))
    ctx.discard(out / TRANSIENT_CHECKPOINT_H5)
