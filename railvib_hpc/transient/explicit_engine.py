"""The ``explicit`` engine: central differences with the lumped mass (Belytschko & Hughes
1983), memory and work per step linear in the DOFs.

Its step is limited by the model's largest natural frequency and the contact spring
(:func:`~.engines.explicit_system`); the absorbing faces' dashpots and the layers'
``M_e1`` are diagonals at the full step, the layers' memory explicit
(:class:`~.explicit.ExplicitSystem`, :class:`~.explicit.ExplicitSolver`).
"""

from __future__ import annotations

from .engine import EngineBase, inject_step


class ExplicitEngine(EngineBase):
    """The explicit engine (:class:`~.engine.Engine`)."""

    name = "explicit"
    lumped = True
    diagonal_dashpots = True

    def stable_step(self, dt_band: float) -> float:
        """Assemble, build the system and its stable step (collective)."""
        from .engines import explicit_system

        m = self.model
        self.assemble()
        with self.rep.stage("transient: stability limit"):
            self.system, dt, self.limit = explicit_system(
                self.ctx, m.mesh, m.dofmap, m.problem, m.rails, m.vehicle,
                (self.K, self.M, self.C, self.dashpots), dt_band, m.pml)
        self.layer = self.system.pml
        self.allowed_step = self.system.allowed_step
        self.dt = inject_step(dt, self.system)
        return self.dt

    def factor(self, n_wheels: int) -> None:
        """Nothing to factor."""

    def make_solver(self, prescribed, driver) -> None:
        """:class:`~.explicit.ExplicitSolver` (the vehicle's contact explicit too)."""
        from .explicit import ExplicitSolver

        self.solver = ExplicitSolver(self.system, prescribed, driver)
        self.static_near_null()

    @property
    def time_pml(self) -> float:
        return float(self.solver.time_pml)

    def initial_acceleration(self, state, loads) -> None:
        """``a_0 = m^-1 (f_0 - C v_0 - d v_0 - K u_0)`` (:func:`~.explicit.
        initial_acceleration`, which starts the layers)."""
        from .explicit import initial_acceleration

        initial_acceleration(self.system, state, loads)
