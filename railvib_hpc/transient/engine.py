"""The time-domain engine protocol of the ``transient`` stage, and its registry lookup.

An engine is built from the model (:class:`EngineModel`: the problem, the mesh, the DOF
map, the rails, the vehicle and the layers' geometry) and then, in this order, by the
run's setup (:func:`~.run_setup.setup_run`):

1. :meth:`Engine.stable_step`: the step it takes, from the band's step (the conditionally
   stable engines assemble first: their step follows from the matrices);
2. :meth:`Engine.factor`: its factor, once the step and the run's size are known (the
   implicit engines; nothing for the explicit one);
3. :meth:`Engine.make_solver`: its stepper with the loads (the prescribed forces, the
   vehicle); then :meth:`Engine.initial_acceleration` at t = 0, :meth:`Engine.step` for
   every step, :meth:`Engine.state` / :meth:`Engine.restore` for the checkpoints (the
   whole state beyond the displacements, velocities and accelerations of
   :class:`~.integrate.State`: the perfectly matched layers' memory), :meth:`describe`
   for the log.

The engines are declared in :data:`railvib_hpc.time_engines.ENGINES` (name, whether they
take layers and the lumped mass, ``"module:factory"``): :func:`build_engine` imports the
declared class only when a run builds it. The stage's loop steps, records and checkpoints
only (as SPECFEM3D's ``iterate_time``).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from ..io.stage_protocol import StageContext
from ..problem import Problem
from ..time_engines import declaration
from .integrate import SparseLoad, State, StepInfo, VehicleDriver
from .rail import RailDofs

#: Rail nodes ahead of each wheel whose columns are computed in one block.
LOOKAHEAD_NODES = 12


@dataclass
class EngineModel:
    """What an engine is built from (collective).

    Attributes
    ----------
    ctx
        The stage's context (case, communicator, reporter).
    mesh, dofmap, problem
        The model (``problem``: the run's, built once from the case).
    rails, vehicle
        The flexible rails' DOFs and the vehicle (None: moving forces or surface loads).
    pml
        The layers' checked :func:`~.pml.pml_geometry` (None without ``pml`` faces).
    """

    ctx: StageContext
    mesh: Any
    dofmap: Any
    problem: Problem
    rails: RailDofs
    vehicle: Any
    pml: tuple | None


class Engine(Protocol):
    """A time-domain engine (see the module notes)."""

    #: ``transient.engine``.
    name: ClassVar[str]
    #: Whether ``transient.implicit_parts`` are integrated implicitly.
    implicit_parts: ClassVar[bool]
    #: The distributed system (products, solves, energies) and the stepper.
    system: Any
    solver: Any
    #: K, M, C (C None when nothing damps) and the damping summary of the assembly.
    K: Any
    M: Any
    C: Any
    damping: dict
    #: The generalized-alpha coefficients (None: the explicit engine).
    scheme: Any
    #: The largest step it allows (None: unconditionally stable).
    allowed_step: float | None
    #: The rail columns of a vehicle (None without, or for the explicit engine).
    columns: Any

    def stable_step(self, dt_band: float) -> float: ...

    def factor(self, n_wheels: int) -> None: ...

    def make_solver(self, prescribed, driver: VehicleDriver | None) -> None: ...

    def initial_acceleration(self, state: State, loads: list[SparseLoad]) -> None: ...

    def step(self, state: State) -> StepInfo: ...

    def state(self) -> dict[str, tuple[str, np.ndarray]]: ...

    def restore(self, saved: dict[str, np.ndarray]) -> None: ...

    def describe(self) -> str: ...

    def destroy(self) -> None: ...


def engine_class(name: str) -> type:
    """The engine class declared for ``name`` (:data:`railvib_hpc.time_engines.ENGINES`,
    its ``"module:attribute"`` imported now)."""
    module, _, attr = declaration(name).factory.partition(":")
    return getattr(importlib.import_module(module), attr)


def build_engine(name: str, model: EngineModel) -> Engine:
    """The engine ``name`` built from ``model`` (collective)."""
    return engine_class(name)(model)


class EngineBase:
    """What the package's engines share: the model, the layers' state, the teardown.

    Subclasses set :attr:`name` and implement :meth:`stable_step`, :meth:`factor`,
    :meth:`make_solver` and :meth:`describe`; :meth:`step` hands over to the stepper.
    """

    name: ClassVar[str] = ""
    #: Whether the mass is lumped (the explicit engines) and the absorbing faces' dashpots
    #: are a diagonal apart from C (the explicit engine).
    lumped: ClassVar[bool] = False
    diagonal_dashpots: ClassVar[bool] = False
    #: Whether ``transient.implicit_parts`` are integrated implicitly (the IMEX engine):
    #: they may not lie in a perfectly matched layer
    #: (:func:`~.engines.check_implicit_outside_layers`).
    implicit_parts: ClassVar[bool] = False

    def __init__(self, model: EngineModel):
        self.model = model
        self.ctx, self.comm, self.rep = model.ctx, model.ctx.comm, model.ctx.rep
        self.system = self.solver = self.scheme = self.columns = None
        self.K = self.M = self.C = None
        self.damping: dict = {}
        self.dashpots = None
        self.allowed_step: float | None = None
        #: The perfectly matched layers (:class:`~.pml.PmlLayer`, or None; the system
        #: owns them).
        self.layer = None
        self.limit = ""
        self.dt = 0.0

    # ------------------------------------------------------------------ building blocks
    def assemble(self) -> None:
        """K, M, C with this engine's mass and dashpots (:func:`.engines.assemble_matrices`;
        the problem gains the supported track ends' springs)."""
        from .engines import assemble_matrices

        m = self.model
        self.K, self.M, self.C, self.damping, self.dashpots, m.problem = assemble_matrices(
            self.ctx, m.mesh, m.dofmap, m.problem, m.pml, lumped=self.lumped,
            diagonal_dashpots=self.diagonal_dashpots)

    def rail_columns_gb(self, rows: int, n_wheels: int) -> float:
        """Memory of the rail columns (:class:`~.integrate.RailColumns`) at most [GB], on
        ``rows`` rows."""
        return 8.0 * rows * 4 * 2 * (LOOKAHEAD_NODES + 3) * n_wheels / 1e9

    def implicit_solver(self, prescribed, driver: VehicleDriver | None) -> None:
        """The factored engines' stepper (:class:`~.integrate.DirectSolver`, with the
        rail columns of a vehicle)."""
        from .integrate import DirectSolver, RailColumns

        if driver is not None:
            self.columns = RailColumns(self.system, self.model.rails, LOOKAHEAD_NODES)
        self.solver = DirectSolver(self.system, prescribed, driver, self.columns)

    def static_near_null(self) -> None:
        """GAMG's near null space for the static start, when it is solved by CG (the
        conditionally stable engines' :meth:`~.explicit.ExplicitSystem.solve_matrix`)."""
        from ..model.dofmap import rigid_body_modes

        m = self.model
        self.system.near_null = lambda: rigid_body_modes(m.mesh.points, m.dofmap,
                                                         self.comm.rank)

    # ------------------------------------------------------------------ the protocol
    @property
    def time_pml(self) -> float:
        """Wall time in the layers' memory terms [s] (the factored engines' system's)."""
        return float(self.system.time_pml)

    def initial_acceleration(self, state: State, loads: list[SparseLoad]) -> None:
        """``a_0`` from the equation of motion at t = 0 (the layers at rest at ``u_0``)."""
        from .integrate import initial_acceleration

        if self.layer is not None:
            self.layer.start(state.u)          # the static field: the layers' rest
        initial_acceleration(self.system, state, loads)

    def start(self, state: State) -> None:
        """Prepare the stepper for ``state`` (the contact load of its step)."""
        self.solver.start(state)

    def step(self, state: State) -> StepInfo:
        """Advance ``state`` by one step in place (collective)."""
        return self.solver.step(state)

    def state(self) -> dict[str, tuple[str, np.ndarray]]:
        """The engine's own state beyond :class:`~.integrate.State` (for a checkpoint):
        ``name: (kind, array)``, kind ``"rows"`` (this rank's rows of a vector over the
        global DOFs) or ``"elements"`` (one row per layer element, the global element
        numbers in ``"elements"``'s own entry); empty without layers."""
        return {} if self.layer is None else self.layer.memory()

    def restore(self, saved: dict[str, np.ndarray]) -> None:
        """Set the state of :meth:`state` back (this rank's part)."""
        if self.layer is not None and saved:
            self.layer.restore(saved)

    def describe(self) -> str:
        """The scheme and its step's limit, for the log."""
        return declaration(self.name).description + self.limit

    def destroy(self) -> None:
        """Free the stepper, the system and the matrices."""
        from ..model.petsc import destroy_damping

        for obj in (self.solver, self.system):
            if obj is not None:
                obj.destroy()
        for A in (self.K, self.M):
            if A is not None:
                A.destroy()
        destroy_damping(self.C)
        self.solver = self.system = self.K = self.M = self.C = None


def gather_state(state: dict[str, tuple[str, np.ndarray]], comm, rows: tuple[int, int],
                 n_dofs: int) -> dict[str, tuple[str, np.ndarray]] | None:
    """An engine's :meth:`~Engine.state` of every rank on rank 0, as global arrays
    (collective; None on the other ranks): ``rows`` entries as vectors over the
    ``n_dofs`` global DOFs (this rank's ``rows = (r0, r1)``), ``elements`` entries with one
    row per element of the union of the ranks' ``ids`` (increasing; an element several
    ranks hold has the same state on each)."""
    parts = comm.gather((rows, state), root=0) if comm.size > 1 else [(rows, state)]
    if comm.rank != 0:
        return None
    out: dict[str, tuple[str, np.ndarray]] = {}
    ids = [np.asarray(s[k][1]) for _, s in parts for k, (kind, _) in s.items()
           if kind == "ids"]
    union = np.unique(np.concatenate(ids)) if ids else np.zeros(0, dtype=np.int64)
    for name, (kind, first) in state.items():
        if kind == "ids":
            out[name] = (kind, union)
        elif kind == "rows":
            full = np.zeros(n_dofs)
            for (r0, r1), s in parts:
                full[r0:r1] = s[name][1]
            out[name] = (kind, full)
        else:
            full = np.zeros((union.size, *np.shape(first)[1:]))
            for _, s in parts:
                own = next(v for k, (kd, v) in s.items() if kd == "ids")
                full[np.searchsorted(union, own)] = s[name][1]
            out[name] = (kind, full)
    return out


def inject_step(dt: float, system=None) -> float:
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


def inject_damping(C) -> None:
    """``C`` times ``-factor`` for a ``"negative_damping"`` :data:`~.guard.TEST_INJECTION`
    (the direct engine's test hook)."""
    from . import guard

    inject = guard.TEST_INJECTION
    if inject is not None and inject.kind == "negative_damping" and C is not None:
        C.scale(-inject.factor)


__all__ = ["LOOKAHEAD_NODES", "Engine", "EngineBase", "EngineModel", "build_engine",
           "engine_class", "gather_state", "inject_damping", "inject_step"]
