"""The ``direct`` engine: generalized-alpha on one MUMPS factor of the effective matrix.

Chung & Hulbert (1993) with ``transient.rho_inf`` (1: Newmark's average acceleration),
unconditionally stable: the step is the band's (:func:`~.stage.time_step`). The consistent
mass, C assembled with the absorbing faces' dashpots, the layers implicit in K_eff
(:class:`~.petsc.TransientSystem`), stepped by :class:`~.integrate.DirectSolver`.
"""

from __future__ import annotations

from .engine import EngineBase, inject_damping


class DirectEngine(EngineBase):
    """The direct engine (:class:`~.engine.Engine`)."""

    name = "direct"

    def stable_step(self, dt_band: float) -> float:
        """The band's step: the scheme is unconditionally stable (nothing assembled yet)."""
        self.dt = float(dt_band)
        return self.dt

    def factor(self, n_wheels: int) -> None:
        """Assemble, build the layers and factor K_eff (collective)."""
        from .engines import pml_layer
        from .petsc import TransientSystem
        from .scheme import GeneralizedAlpha

        m, case = self.model, self.ctx.case
        self.assemble()
        self.layer = pml_layer(self.ctx, m.mesh, m.dofmap, m.problem, self.K, m.pml)
        inject_damping(self.C)
        with self.rep.stage("transient: factorization"):
            self.scheme = GeneralizedAlpha.from_radius(self.dt, case["transient.rho_inf"])
            self.system = TransientSystem(
                self.K, self.M, self.C, self.scheme, self.comm, pml=self.layer,
                extra_gb=self.rail_columns_gb(m.dofmap.n_dofs, n_wheels))
            system = self.system
            self.rep.info(f"  MUMPS Cholesky of K_eff: {system.time_factorization:.2f} s, "
                          f"factor ~{system.factor_memory_gb:.2f} GB"
                          + (" (out of core)" if system.out_of_core else ""))

    def make_solver(self, prescribed, driver) -> None:
        """:class:`~.integrate.DirectSolver` with the rail columns of a vehicle."""
        self.implicit_solver(prescribed, driver)

    def state(self) -> dict:
        """The layers' memory and their force at the last step (the history's part of the
        next right-hand side, :meth:`~.petsc.TransientSystem.history_rhs_layers`)."""
        out = super().state()
        if self.layer is not None:
            out["system_pml_force"] = ("rows", self.system.pml_force.copy())
        return out

    def restore(self, saved: dict) -> None:
        super().restore(saved)
        if self.layer is not None and "system_pml_force" in saved:
            self.system.pml_force = saved["system_pml_force"].copy()

    def describe(self) -> str:
        return f"generalized-alpha rho_inf = {self.ctx.case['transient.rho_inf']:g}"
