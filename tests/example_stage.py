"""A new stage in one module: ``example`` writes ``example.json`` (tests/test_stage_protocol.py).

Its declaration is all a stage needs: its name and help line, its product (here a new
row of the one product table, declared with it), what it reads and ``compute``. Registered
with one line (``railvib_hpc.pipeline.STAGES["example"] = "example_stage"``) it runs from
the Python API and the command line, through the same runner as the package's stages:
the lock, the reuse verdict and its message, provenance, ``run.json`` and the timing.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

from railvib_hpc.io.atomic import write_json
from railvib_hpc.io.products import StageFile
from railvib_hpc.io.stage_protocol import Stage, StageContext, StageOutput
from railvib_hpc.parallel import on_root

#: The product: ``example.json``, format 1, computed from ``vehicle.speed`` only.
PRODUCT = StageFile("example.json", "example", 1, (("vehicle.speed", ()),))


@dataclass(frozen=True)
class ExampleOutput(StageOutput):
    """What the example stage returns: the vehicle's speed squared [m²/s²]."""

    speed_squared: float


def compute(ctx: StageContext) -> ExampleOutput:
    """Reuse ``example.json`` when it is current, else compute and write it (rank 0)."""
    path = ctx.path("example.json")

    def work() -> ExampleOutput:
        old = ctx.reuse("example.json", why="same vehicle speed",
                        accept=lambda v: json.loads(path.read_text())["speed_squared"])
        value = old.value if old.ok else ctx.case["vehicle.speed"] ** 2
        if not old.ok:
            write_json(path, {"speed_squared": value}, ctx.provenance("example.json", {}))
            ctx.rep.info(f"wrote {path}")
        return ExampleOutput(reused=old.ok, summary={"reused": old.ok, "speed_squared": value},
                             speed_squared=value)

    return on_root(work, ctx.comm)


STAGE = Stage(name="example", help="write example.json: the vehicle's speed squared",
              products=(PRODUCT,), compute=compute)
