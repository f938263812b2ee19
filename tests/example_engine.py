"""A new time-domain engine in one module: ``halfstep``, the explicit engine's central
differences at half its stable step (tests/test_engine_protocol.py).

Its declaration is all the package needs of it: the name, its line for the log and the
assessment, where the class lives (imported only when a run builds it), that it needs the
lumped mass and takes layers. Registered with one line
(``railvib_hpc.time_engines.ENGINES["halfstep"] = DECLARATION``) it is a choice of
``transient.engine`` (the schema, the validation, the dispersion check and the assessment
read the table) and runs from the command line and the Python API through the transient
stage's one loop, with its checkpoints.
"""

from __future__ import annotations

from railvib_hpc.time_engines import EngineDeclaration
from railvib_hpc.transient.explicit_engine import ExplicitEngine

#: The engine's declaration (its one registry line adds it to the table).
DECLARATION = EngineDeclaration(
    "halfstep", "central differences at half the stable step (example), ",
    "example_engine:HalfStepEngine", lumped_mass=True,
    report="central differences at half the stable step (example), lumped mass, ")


class HalfStepEngine(ExplicitEngine):
    """The explicit engine at half the step it would take (:class:`~railvib_hpc.transient.
    engine.Engine`): the same system and stepper, the step halved (it still divides
    ``output.dt``)."""

    name = "halfstep"

    def stable_step(self, dt_band: float) -> float:
        self.dt = 0.5 * super().stable_step(dt_band)
        self.system.dt = self.dt
        return self.dt
