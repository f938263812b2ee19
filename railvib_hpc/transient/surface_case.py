"""The case's moving surface load (``track.count = 0``, ``[load]``; docs/transient.md).

A site without a track: the bare soil (and the building) of the generated mesh, loaded by
the vertical point loads of ``[load]`` moving along ``x`` on the ground line ``y =
load.y``, ``z = geometry.z1`` (:class:`~railvib_hpc.transient.surface_load.MovingSurfaceLoad`,
the load of the half-space verification, tests/transient/test_moving_load_halfspace.py),
instead of the vehicle on the rails. The stage (:mod:`railvib_hpc.transient.stage`) runs
it as the moving forces of ``vehicle.type = 'moving_force'`` are run, with no wheel, no
rail and no vehicle DOF: ``transient.h5`` holds empty wheel and rail tables, ``probes.h5``
no rail group.

The passage: the leading load starts at ``load.x_start``, the run ends when the last one
reaches ``load.x_end`` (0: the soil's end, ``geometry.x4 + domain.extra_length``), then
``load.t_after`` more.
"""

from __future__ import annotations

import numpy as np

from ..config import Case
from ..mesh.model import Mesh
from .rail import RailDofs
from .surface_load import MovingSurfaceLoad, SurfaceLoadPath

__all__ = ["element_time", "no_rails", "surface_load", "surface_passage", "uses_surface_load"]


def uses_surface_load(case: Case) -> bool:
    """Whether the case runs the moving surface load (``track.count = 0``) instead of a
    train."""
    return case["track.count"] == 0


def run_up_time(case: Case) -> float:
    """The loads' run-up [s]: ``load.ramp_time`` with ``load.start = 'static'`` (the loads
    stand in static equilibrium at t = 0 and reach their speed over it), 0 otherwise (the
    ramp switches the forces on instead)."""
    return float(case["load.ramp_time"]) if case["load.start"] == "static" else 0.0


def soil_end(case: Case) -> float:
    """x of the soil's end [m]: ``geometry.x4 + domain.extra_length``."""
    return float(case["geometry.x4"] + case["domain.extra_length"])


def surface_passage(case: Case) -> dict:
    """The passage of the surface loads, with the keys of
    :func:`~railvib_hpc.mbs.case_vehicle.passage` (no wheel on a rail).

    Returns
    -------
    dict
        ``forces`` (n,) [N], ``offsets`` (n,) [m], ``x_start`` [m], ``speeds`` (n,) [m/s],
        ``wheel_rail`` (empty), ``x_end`` [m] and ``t_end`` [s]: when the last load reaches
        ``x_end``, plus ``load.t_after``.

    Examples
    --------
    >>> from railvib_hpc.config import Case
    >>> run = surface_passage(Case.from_dict({"track.count": 0, "load.force": 1e4,
    ...                                       "load.speed": 50.0, "load.x_end": 20.0}))
    >>> round(run["t_end"], 6), run["wheel_rail"].size
    (0.4, 0)
    """
    ld = case["load"]
    offsets = np.asarray(ld["offsets"], dtype=float)
    x_end = ld["x_end"] or soil_end(case)
    # a static start's run-up (load.ramp_time) costs half its time (run_up_distance)
    t_end = ((x_end - ld["x_start"] - offsets.min()) / ld["speed"] + ld["t_after"]
             + 0.5 * run_up_time(case))
    return {"forces": np.full(offsets.size, float(ld["force"])), "offsets": offsets,
            "x_start": float(ld["x_start"]), "speeds": np.full(offsets.size, ld["speed"]),
            "wheel_rail": np.zeros(0, dtype=np.int64), "x_end": float(x_end),
            "t_end": float(t_end)}


def no_rails() -> RailDofs:
    """The rails of a model without a track: none (the samplers and tables stay empty)."""
    return RailDofs(nodes=np.zeros((0, 2), dtype=np.int64), x=np.zeros((0, 2)),
                    y=np.zeros(0), dofs=np.full((0, 2, 4), -1, dtype=np.int64))


def element_time(mesh: Mesh, speed: float) -> float:
    """Time the load takes to cross the shortest element edge along x [s] (the automatic
    step crosses it in ``transient.steps_per_element`` steps, as a wheel a rail element)."""
    edges = np.diff(np.unique(np.round(mesh.points[:, 0], 9)))
    return float(edges.min()) / speed


def surface_load(case: Case, mesh: Mesh, dof_index: np.ndarray, dt: float,
                 nt: int) -> MovingSurfaceLoad:
    """The nodal loads of ``[load]`` at every step (the consistent loads of the elements
    under the ground line ``y = load.y``, ``z = geometry.z1``).

    Raises
    ------
    ValueError
        The loads never stand on the ground (the path beside the soil, or in the building's
        plan or an open trench all along).
    """
    ld = case["load"]
    run = surface_passage(case)
    path = SurfaceLoadPath(forces=run["forces"], offsets=run["offsets"],
                           x_start=run["x_start"], y=float(ld["y"]), speed=float(ld["speed"]),
                           ramp_time=(0.0 if ld["start"] == "static"
                                      else float(ld["ramp_time"])),
                           run_up=run_up_time(case),
                           half_width=float(ld["half_width"]),
                           frequency=float(ld["frequency"]))
    return MovingSurfaceLoad(mesh, dof_index, path, dt, nt, ground=case["geometry.z1"])
