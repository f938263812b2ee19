"""The ``imex`` engine: implicit-explicit Newmark (Hughes & Liu 1978).

The elements of ``transient.implicit_parts`` (and with ``transient.implicit_elements =
'auto'`` the stiffest soil elements) by the trapezoidal rule on one small MUMPS factor,
the rest explicit with the lumped mass: the step is limited by the explicit part only
(:func:`~.engines.imex_partition`, :class:`~.imex.ImexSystem`), stepped by
:class:`~.integrate.DirectSolver`.
"""

from __future__ import annotations

from .engine import EngineBase, inject_step


class ImexEngine(EngineBase):
    """The IMEX engine (:class:`~.engine.Engine`)."""

    name = "imex"
    lumped = True
    implicit_parts = True

    def stable_step(self, dt_band: float) -> float:
        """Assemble, partition and the explicit part's stable step (collective)."""
        from .engines import imex_partition

        m = self.model
        self.assemble()
        with self.rep.stage("transient: stability limit"):
            self.partition, dt, self.limit, self.layer, self.allowed_step = imex_partition(
                self.ctx, m.mesh, m.dofmap, m.problem, self.K, self.M, self.C, dt_band,
                m.pml)
        self.dt = inject_step(dt)
        return self.dt

    def factor(self, n_wheels: int) -> None:
        """The implicit partition's factor (collective)."""
        from .imex import ImexSystem

        with self.rep.stage("transient: factorization"):
            self.system = system = ImexSystem(
                self.K, self.M, self.C, *self.partition, self.dt, self.comm, pml=self.layer,
                extra_gb=lambda rows: self.rail_columns_gb(rows, n_wheels))
            self.scheme = system.scheme
            self.rep.info(f"  MUMPS Cholesky of K_eff: {system.time_factorization:.2f} s, "
                          f"factor ~{system.factor_memory_gb:.2f} GB"
                          + (" (out of core)" if system.out_of_core else "")
                          + f"; {system.implicit_rows:,} of {self.model.dofmap.n_dofs:,} "
                            "rows implicit")

    def make_solver(self, prescribed, driver) -> None:
        """:class:`~.integrate.DirectSolver` on the IMEX system, with the rail columns of a
        vehicle (on the implicit rows)."""
        self.implicit_solver(prescribed, driver)
        self.static_near_null()
