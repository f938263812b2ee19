"""Wave speeds of the subgrade and the detection of a wave's arrival in a probe history."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..problem import Problem

__all__ = ["wave_arrival", "wave_speeds"]


def wave_speeds(problem: Problem) -> tuple[float, float]:
    """P- and S-wave speeds of the subgrade [m/s]; of the top soil layer when the soil is
    layered (``soil.layers``: the path along the surface; a head wave through a stiffer
    layer below can arrive earlier at a distance)."""
    from ..fem.boundary import wave_speeds as material_wave_speeds
    from ..schema import SOIL_LAYER_PARTS

    top = SOIL_LAYER_PARTS[0]
    mat = problem.material(top if top in problem.materials else "subgrade")
    c_p, c_s = material_wave_speeds(mat.E, mat.nu, mat.rho)
    return float(c_p), float(c_s)


def wave_arrival(t: np.ndarray, acceleration: np.ndarray, t_entry: float,
                 threshold: float) -> float:
    """First time after ``t_entry`` with ``|a| >= threshold * peak`` (NaN: never)."""
    mag = np.linalg.norm(acceleration, axis=1)
    after = t >= t_entry
    if not after.any():
        return float("nan")
    peak = mag[after].max()
    if peak <= 0.0:
        return float("nan")
    idx = np.flatnonzero(after & (mag >= threshold * peak))
    return float(t[idx[0]]) if idx.size else float("nan")
