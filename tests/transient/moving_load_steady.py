"""The surface load's static start against the steady state of a load moving over a
half-space: a harness for any soil (trilinear now; the spectral soil passes its own
overrides).

A case without a track and without a building (``track.count = 0``, ``building.present =
false``) is run through ``railvib transient`` (:func:`run_box`): one point load, spread
over ``load.half_width``, standing in static equilibrium at ``x_start`` at t = 0
(``load.start = 'static'``), running up to its speed over :data:`RUN_UP` metres and on over
receivers beside its path (a ``[[probes.line]]`` :data:`AHEAD` beyond the end of the
run-up: near the start). Each receiver's vertical surface displacement and velocity are
compared, from the end of the run-up on, with the steady state of
:mod:`railvib_hpc.fem.halfspace` convolved with the same spreading (:func:`compare`), the
FE signal without its content above the grid's band (:func:`resolved_band`).

The tolerance (``tol`` of :func:`compare`) is derived, not fitted to the moving reference:

* **the boundaries**: below the Rayleigh speed the field is quasi-static, so what the
  truncated box does to it is what it does to the static field; that is measured on the
  same run at t = 0, where the static start is the box's static answer, against
  Boussinesq's (the reference's ``c -> 0`` limit, spread alike): ``e_box = |u_0 /
  u_Boussinesq - 1|`` at the receiver;
* **the grid**: the receiver's signal is a near field of wavelengths ``2 pi / k`` with
  ``k d`` up to :data:`TOP_KD` (the spectrum of ``1 / r`` beside a line, ``K_0(k d)``, has
  fallen to 2 % there); its error is the grid's Rayleigh-wave dispersion
  (:func:`railvib_hpc.fem.dispersion_rayleigh.worst_surface_error`, the worse of a grid
  axis and a face diagonal, the lumped mass with central differences at the run's
  Courant number and without) at that wavelength over one wavelength of travel (the
  field moves with the load; a receiver is never farther than that from the part of the
  field it sees): ``e_grid``.

The start's own transient is not in the tolerance: the comparison begins at the end of
the run-up, and ``e_*_late`` (after the Rayleigh wave from the start has crossed the
receiver) shows how much of an error is still the start's.

``tol = e_box + e_grid``, for the displacement and the velocity alike (the velocity is
``-c`` times the slope of the same field along the path).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from railvib_hpc.config import Case, load_case
from railvib_hpc.fem.dispersion import critical_courant
from railvib_hpc.fem.dispersion_rayleigh import worst_surface_error
from railvib_hpc.fem.halfspace import moving_load_displacement, moving_load_velocity
from railvib_hpc.site import rayleigh_speed
from railvib_hpc.transient.surface_case import run_up_time
from railvib_hpc.transient.surface_load import SPREAD_SPACING, run_up_distance, spreading

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The loads' run-up [m] (``load.start = 'static'``: they stand in static equilibrium at
#: t = 0 and reach their speed over this distance, ``load.ramp_time`` twice it over the
#: speed): the sudden start of a load standing still radiates the difference between its
#: moving and its static field (measured on this box at 0.6 c_R, 5 m beside the path:
#: v_z 306 % off the steady state's peak with no run-up, 94 % with 10 m).
RUN_UP = 10.0
#: Receivers' distance ahead of the end of the run-up along x [m]: near the start.
AHEAD = 5.0
#: ``k d`` where the spectrum of the receiver's signal, ``K_0(k d)`` of the ``1/r``
#: near field, has fallen to 2 % of its value at ``k d = 0.5`` (``K_0(4) = 0.0112``,
#: ``K_0(0.5) = 0.924``... of the velocity, ``k K_0``, 5 %): the top of what the grid must
#: carry.
TOP_KD = 4.0
#: Fraction of the critical step the explicit engine takes (its ``STEP_SAFETY``).
STEP_SAFETY = 0.9

#: The box of the trilinear soil: the thesis subgrade with nu = 1/4 (c_S 207.8, c_R
#: 191.2 m/s), 1 m cubes, absorbing faces with the springs of docs/verification.md's rule
#: (virtual_thickness about 1.5-2.3 times the faces' distance from the load, 20-25 m
#: here), no damping, the explicit engine.
BOX = ["track.count=0", "building.present=false", "load.force=1e5", "load.start=static",
       "load.half_width=3", "load.y=0", "materials.subgrade.nu=0.25", "damping.model=none",
       "mesh.layout=refined", "mesh.size_far=1", "mesh.size_deep=1",
       "modal.lumped_mass=true", "transient.engine=explicit", "transient.f_max=40",
       "transient.checkpoint_interval=0", "output.stress_times=[]", "output.dt=0.005",
       *(f"boundary.{f}=absorbing" for f in ("x_min", "x_max", "y_min", "y_max", "base")),
       "boundary.virtual_thickness=48"]


def box_overrides(speed_ratio: float, distances=(5.0, 10.0, 20.0), x_start: float = 18.0,
                  length: float = 60.0, half_width: float = 35.0, depth: float = 20.0,
                  run_up: float = RUN_UP, extra: tuple[str, ...] = ()) -> list[str]:
    """The overrides of :data:`BOX` for a load at ``speed_ratio`` c_R starting at
    ``x_start`` (the soil from x = 3 m, ``length`` long (whole sleeper bays of 0.6 m),
    ``half_width`` on either side of the path, ``depth`` (> 4.8 m) deep), receivers
    ``distances`` beside the path at ``x_start + AHEAD``; the run ends when the load has
    passed them by the largest distance.
    ``extra``: further overrides (a spectral soil's)."""
    c_r = rayleigh_speed(math.sqrt(200e6 / (2 * 1.25 * 1850.0)), 0.25)
    ramp_time = 2.0 * run_up / (speed_ratio * c_r) if run_up > 0 else 0.0
    x_r = x_start + run_up + AHEAD                                  # ahead of the run-up
    x_end = x_r + max(distances)
    # (the baseline file lists every key: the geometry keys themselves, not [site]'s)
    return [*BOX, f"track.rail_length={length}", f"geometry.x4={3.0 + length}",
            f"domain.extra_depth={depth - 4.8}",
            f"geometry.ys0={half_width}", f"geometry.ys4={-half_width}",
            f"load.speed={speed_ratio * c_r:.6g}", f"load.x_start={x_start}",
            f"load.x_end={x_end}", f"load.ramp_time={ramp_time:.6g}",
            f"probes.line=[{{name = 'r', x = {x_r}, distances = {list(distances)}}}]",
            *extra]


@dataclass
class BoxRun:
    """A run's receivers: times, vertical displacement and velocity (upwards, as stored),
    their distances and x, the case and the run's statistics."""

    case: Case
    t: np.ndarray
    uz: np.ndarray
    vz: np.ndarray
    distances: np.ndarray
    x: float
    stats: dict


def run_box(folder: Path, overrides: list[str], comm) -> BoxRun:
    """``railvib transient`` of the box (:func:`box_overrides`) into ``folder``."""
    from railvib_hpc.io.formats.probes import read_probes
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    case = load_case(BASELINE, overrides)
    stats = run_transient_stage(case, folder, comm, Reporter(comm.rank))
    hist = read_probes(folder / "probes.h5")
    names = [n for n, h in hist.items() if h["role"] == "free_field"]
    names.sort(key=lambda n: abs(hist[n]["coords"][1]))
    return BoxRun(case, hist[names[0]]["t"],
                  np.stack([hist[n]["displacement"][:, 2] for n in names], axis=1),
                  np.stack([hist[n]["velocity"][:, 2] for n in names], axis=1),
                  np.array([abs(hist[n]["coords"][1] - case["load.y"]) for n in names]),
                  float(hist[names[0]]["coords"][0]), stats)


def soil(case: Case) -> dict:
    """``mu``, ``nu``, ``c_s``, ``c_r`` of the homogeneous subgrade."""
    m = case["materials.subgrade"]
    mu = m["E"] / (2.0 * (1.0 + m["nu"]))
    c_s = math.sqrt(mu / m["rho"])
    return {"mu": mu, "nu": m["nu"], "c_s": c_s, "c_r": rayleigh_speed(c_s, m["nu"])}


def _spread(case: Case, h: float) -> tuple[np.ndarray, np.ndarray]:
    return spreading(case["load.half_width"], SPREAD_SPACING * h)


def steady(case: Case, xi: np.ndarray, d: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """The steady downward displacement and velocity at ``xi`` ahead of the load, ``d``
    beside its path, convolved with its spreading (``h``: the grid's edge along x)."""
    s = soil(case)
    offsets, share = _spread(case, h)
    args = (case["load.force"], s["mu"], s["nu"], s["c_s"], case["load.speed"])
    pts = xi[:, None] - offsets[None, :]
    return (moving_load_displacement(pts, d, *args) @ share,
            moving_load_velocity(pts, d, *args) @ share)


def boussinesq(case: Case, xi: float, d: float, h: float) -> float:
    """The static settlement under the spread load (the steady state's ``c -> 0`` limit,
    Boussinesq's ``P (1 - nu) / (2 pi mu r)`` summed over the spreading)."""
    s = soil(case)
    offsets, share = _spread(case, h)
    r = np.hypot(xi - offsets, d)
    return float(case["load.force"] * (1.0 - s["nu"]) / (2.0 * math.pi * s["mu"] * r) @ share)


def grid_error(case: Case, d: float, h: float, dt: float) -> float:
    """``e_grid`` of the module notes at distance ``d`` (edge ``h``, step ``dt``)."""
    s = soil(case)
    n_r = 2.0 * math.pi * d / (TOP_KD * h)          # elements per wavelength at k d = TOP_KD
    c_p = s["c_s"] * math.sqrt(2.0 * (1.0 - s["nu"]) / (1.0 - 2.0 * s["nu"]))
    courant = min(c_p * dt / h, STEP_SAFETY * critical_courant(s["nu"]))
    err, _ = worst_surface_error(n_r, 1.0, s["nu"], "lumped",
                                 (("none", 0.0), ("central", courant)))
    return float(err)


def resolved_band(case: Case, h: float) -> float:
    """The band the grid resolves [Hz]: ``mesh.min_elements_per_wavelength`` elements per
    shear wavelength, ``c_S / (n h)`` (35 Hz on 1 m cubes of the thesis subgrade): what
    lies above is the grid's own response, not the soil's."""
    return soil(case)["c_s"] / (case["mesh.min_elements_per_wavelength"] * h)


def low_pass(signal: np.ndarray, t: np.ndarray, band: float) -> np.ndarray:
    """``signal`` without its content above ``band`` (a 4th-order Butterworth forwards
    and backwards: no phase shift), its value at t = 0 kept as the level before it."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(4, band, fs=1.0 / (t[1] - t[0]), output="sos")
    return sosfiltfilt(sos, signal - signal[0], padtype="constant") + signal[0]


def compare(run: BoxRun) -> list[dict]:
    """Per receiver: the errors of the displacement and the velocity against the steady
    state (the largest difference after ``t_settle``, over the reference's largest value
    there), the static start's settlement against Boussinesq (``e_box``), ``e_grid``, the
    tolerance and the window."""
    case = run.case
    s = soil(case)
    h = case["mesh.size_far"] / case["mesh.refinement"]
    dt = run.stats["dt"]
    run_up = run_up_time(case)
    lead = case["load.x_start"] + case["load.speed"] * run_up_distance(run.t, run_up)
    xi = run.x - lead
    at_speed = run.t >= run_up          # the steady state is the load's at its speed
    out = []
    for j, d in enumerate(run.distances):
        w, v = steady(case, xi[at_speed], d, h)
        fe_w, fe_v = -run.uz[at_speed, j], -run.vz[at_speed, j]   # downwards, as w
        # the start's difference leaves the receiver at the Rayleigh speed
        t_settle = math.hypot(run.x - case["load.x_start"], d) / s["c_r"]
        late = run.t[at_speed] >= t_settle
        e_box = abs(-run.uz[0, j] / boussinesq(case, xi[0], d, h) - 1.0)
        e_grid = grid_error(case, d, h, dt)
        row = {"d": float(d), "speed": case["load.speed"], "t_settle": t_settle,
               "e_box": e_box, "e_grid": e_grid, "tol": e_box + e_grid,
               "u0_static": abs(fe_w[0] / w[0] - 1.0), "run_up": run_up}
        band = resolved_band(case, h)
        for key, fe, ref in (("u", fe_w, w), ("v", fe_v, v)):
            low = low_pass(fe, run.t[at_speed], band)
            row[f"e_{key}"] = float(np.abs(low - ref).max() / np.abs(ref).max())
            row[f"e_{key}_raw"] = float(np.abs(fe - ref).max() / np.abs(ref).max())
            row[f"e_{key}_late"] = float(np.abs(low - ref)[late].max()
                                         / np.abs(ref[late]).max())
        row["band"] = band
        out.append(row)
    return out


def format_rows(rows: list[dict], c_r: float) -> str:
    """The comparison as a table (speed, distance, errors, tolerance)."""
    lines = [f"{'c/c_R':>6s} {'d [m]':>6s} {'u_z':>8s} {'v_z':>8s} {'tol':>7s} "
             f"{'e_box':>7s} {'e_grid':>7s} {'u_z raw':>8s} {'v_z raw':>8s} "
             f"{'u_z late':>8s} {'v_z late':>8s} {'t_settle':>8s}"]
    for r in rows:
        lines.append(f"{r['speed'] / c_r:6.2f} {r['d']:6.1f} {r['e_u']:8.2%} {r['e_v']:8.2%} "
                     f"{r['tol']:7.2%} {r['e_box']:7.2%} {r['e_grid']:7.2%} "
                     f"{r['e_u_raw']:8.2%} {r['e_v_raw']:8.2%} {r['e_u_late']:8.2%} "
                     f"{r['e_v_late']:8.2%} {r['t_settle']:8.3f}")
    return "\n".join(lines)
