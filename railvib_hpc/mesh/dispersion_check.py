"""The mesh check's numerical dispersion at the farthest probe (docs/transient.md).

A wave of ``mesh.wavelength_hz`` that travels from the track to the farthest probe
accumulates the grid's phase error (:mod:`railvib_hpc.fem.dispersion`): the check predicts
the resulting peak-velocity error there and refuses a band the mesh cannot resolve.

Conservative choices, each an upper bound of what it replaces:

* the distance is the largest horizontal distance, across the track, from any track's
  centre line (y = 0 and ``track.spacing``) to any probe: the mesh's named probes,
  ``output.probes`` and the points of ``[[probes.line]]``;
* the whole path is taken in the ground part (``subgrade``, ``soil_layer_k``) with the
  largest predicted error, with its longest element edge as the edge of a cubic grid
  (the embankment's ballast and the mitigation measures are crossed over a few metres only
  and are left out);
* the wave is the Rayleigh wave that carries most of the energy to a surface probe, with
  the grid's own Rayleigh relation in the worse of a grid axis and a face diagonal: of the
  trilinear grid (``mesh.order = 1``, :mod:`railvib_hpc.fem.dispersion_rayleigh`, checked
  against FE runs within 2.5 %; the diagonal, 1.8 times the axis's lag for the lumped
  mass; the bulk S relation at the Rayleigh wavelength, the check's proxy before, gave
  9-11 % less lag), or of the spectral grid of order ``N = mesh.order`` (a periodic column
  of GLL elements, :func:`railvib_hpc.fem.dispersion_gll_rayleigh.checked_surface_error`:
  along the directions where it is worst,
  :data:`~railvib_hpc.fem.spectral_advice.SURFACE_DIRECTIONS`, with its diagonal GLL mass,
  the worst over a 2 % window about the band's top, whose zone boundaries ``k h = m pi``
  the relation cannot be read at, and unresolved below 4 points per wavelength).
  "Elements per wavelength" are elements, ``N`` points each;
* the error is the harmonic bound of :func:`~railvib_hpc.fem.dispersion.peak_velocity_error`
  at the band's top frequency, the larger of the semidiscretisation (the modal path, and a
  step tending to 0) and the transient engine at its largest step (``transient.dt`` or the
  automatic step's bound ``1 / (transient.steps_per_period transient.f_max)`` for the
  direct engine; for the explicit ones the soil grid's own limit, 0.9 of its critical step
  (of the trilinear grid, or of the GLL grid of order N,
  :func:`~railvib_hpc.fem.dispersion_gll.critical_courant`), which only lowers the lumped
  mass's lag): the time scheme's error is monotone in the step and of the opposite sign, so
  the worst lies at one of the two ends.

For a spectral soil the advice names the elements per wavelength at the case's order and at
the next one (with the DOFs per cubic metre of each; :mod:`railvib_hpc.fem.spectral_advice`
compares all orders, a minute's search at orders 7-8, too slow for every run).

The check runs after meshing, with the measured edges, and before ``mesh.h5`` is written;
on a reused mesh it runs again (``output.probes`` and the limits are not mesh inputs).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from ..config import Case
from ..constants import THIRD_OCTAVE_MANTISSAS
from ..errors import MeshError
from ..fem import dispersion_gll, dispersion_gll_rayleigh
from ..fem.boundary import wave_speeds
from ..fem.dispersion import critical_courant, elements_needed
from ..fem.dispersion_gll_rayleigh import MIN_POINTS_PER_WAVELENGTH
from ..fem.dispersion_rayleigh import worst_surface_error
from ..fem.gll import MAX_ORDER
from ..fem.spectral_advice import SURFACE_DIRECTIONS
from ..schema import SOIL_LAYER_PARTS
from ..time_engines import EngineNames, declaration

#: The accuracy the mesh check aims at: below 5 % peak-velocity error at the farthest
#: probe; a larger predicted error is warned about.
DISPERSION_TARGET = 0.05
#: Phase error at the farthest probe, in periods of the band's top frequency, from which the
#: mesh cannot resolve the band there: the wave arrives in antiphase (the harmonic bound has
#: long reached 100 %, at a quarter period).
UNRESOLVED_PHASE = 0.5
#: Fraction of the critical step the explicit engines take (``STEP_SAFETY`` of
#: :mod:`railvib_hpc.transient.explicit`, which the mesh layer cannot import; a test keeps
#: the two equal).
EXPLICIT_STEP_SAFETY = 0.9
#: Where the advice's search for another order starts, a fraction of the case's elements
#: per wavelength (the next order needs 0.5-0.8 of them at the same error: docs/spectral.md's
#: advice table).
_OTHER_ORDER_START = 0.25
#: The root search's relative tolerance of the elements per wavelength advised, trilinear
#: and spectral: the advice is rounded up to a tenth, 0.3-1 % of the trilinear grid's
#: 10-30 per wavelength and 3-20 % of the spectral grid's 0.5-3 (each evaluation of the GLL
#: relation is a sparse eigenproblem, 10-50 ms).
_ADVICE_RTOL = (2e-3, 1e-2)
#: The ground parts a wave crosses on its way to the probes.
GROUND_PARTS = ("subgrade", *SOIL_LAYER_PARTS)
#: Engines whose soil is integrated with central differences and the lumped mass (read
#: from the engines' declarations, :data:`railvib_hpc.time_engines.ENGINES`).
EXPLICIT_ENGINES = EngineNames(lambda d: d.soil_scheme == "central")


class DispersionError(MeshError):
    """A band the mesh cannot resolve at the farthest probe (``mesh.max_dispersion_error``)."""


@dataclass(frozen=True)
class SoilGrid:
    """The soil element the check predicts for (:func:`soil_grid`).

    Attributes
    ----------
    order
        ``mesh.order``: 1 the trilinear hexahedron, 2..8 spectral (GLL) elements.
    worst
        Its Rayleigh relation's worst error, ``worst(epw, wavelengths, nu=, schemes=,
        measure=) -> (error, where)`` (``epw`` elements per Rayleigh wavelength).
    critical
        Its critical Courant number ``c_P dt / h`` of central differences, of ``nu``.
    mass
        The words for its mass in the report (``"lumped mass"``).
    """

    order: int
    worst: Callable[..., tuple[float, str]]
    critical: Callable[[float], float]
    mass: str


def soil_grid(case: Case, order: int | None = None) -> SoilGrid:
    """The case's soil element (``order``: another order of the same case, the advice's).

    >>> from railvib_hpc.config import Case
    >>> soil_grid(Case.defaults()).mass, soil_grid(Case.defaults(), 4).mass
    ('consistent mass', 'spectral order 4, diagonal GLL mass')
    """
    order = case["mesh.order"] if order is None else order
    if order == 1:
        formulation = case["modal.hex_formulation"]
        return SoilGrid(1, partial(worst_surface_error, mass=_mass(case),
                                   rho_inf=case["transient.rho_inf"], formulation=formulation),
                        partial(critical_courant, formulation=formulation),
                        f"{_mass(case)} mass")
    return SoilGrid(order, partial(dispersion_gll_rayleigh.checked_surface_error, order=order,
                                   rho_inf=case["transient.rho_inf"],
                                   directions=SURFACE_DIRECTIONS[order]),
                    partial(dispersion_gll.critical_courant, order),
                    f"spectral order {order}, diagonal GLL mass")


def rayleigh_ratio(nu: float) -> float:
    """``c_R / c_S`` (Viktorov 1967, "Rayleigh and Lamb Waves": ``(0.862 + 1.14 nu) /
    (1 + nu)``, within 1.5 % of the exact root for ``0 <= nu <= 0.5``, 0.2 % at 0.25).

    >>> round(rayleigh_ratio(0.25), 4)
    0.9176
    """
    return (0.862 + 1.14 * nu) / (1.0 + nu)


def track_centres(case: Case) -> tuple[float, ...]:
    """y of the track centre lines: track 1 at 0, track 2 ``track.spacing`` further from
    the building (:class:`~railvib_hpc.mesh.layout.Layout`)."""
    return (0.0,) + ((float(case["track.spacing"]),) if case["track.count"] == 2 else ())


def farthest_probe(case: Case, probes: Mapping[str, Any]) -> tuple[str, float, int]:
    """The probe farthest across the track from any track centre line.

    Returns
    -------
    name, distance, track : str, float, int
        The probe, its distance [m] and the track (1 or 2); ``("", 0.0, 1)`` without probes.
    """
    from ..site import line_probes

    points = {k: tuple(v) for k, v in probes.items()}
    user = np.asarray(case["output.probes"], dtype=float).reshape(-1, 3)
    points.update({f"user_{i + 1}": tuple(p) for i, p in enumerate(user)})
    points.update({k: p.point for k, p in line_probes(case).items()})
    best = ("", 0.0, 1)
    for name, p in points.items():
        for k, y in enumerate(track_centres(case), start=1):
            d = abs(float(p[1]) - y)
            if d > best[1]:
                best = (name, d, k)
    return best


def _schemes(case: Case, c_p: float, c_r: float, f: float, nu: float,
             dt: float | None = None, grid: SoilGrid | None = None
             ) -> Callable[[float], tuple[tuple[str, float], ...]]:
    """The ``(scheme, courant)`` ends of the step range, as a function of the elements per
    Rayleigh wavelength ``n`` (the element edge is ``c_R / (f n)``); ``dt``: the run's own
    step (the transient stage's check), else its bound from the case; ``grid``: the soil
    element (default the case's, :func:`soil_grid`)."""
    scheme = declaration(case["transient.engine"]).soil_scheme
    if scheme == "central":
        cc = EXPLICIT_STEP_SAFETY * (grid or soil_grid(case)).critical(nu)
        if dt is not None:
            return lambda n: (("none", 0.0), ("central", min(c_p * dt * f * n / c_r, cc)))
        return lambda n: (("none", 0.0), ("central", cc))
    if scheme == "generalized_alpha":
        if dt is None:
            dt = case["transient.dt"] or 1.0 / (case["transient.steps_per_period"]
                                                * case["transient.f_max"])
        return lambda n: (("none", 0.0), ("generalized_alpha", c_p * dt * f * n / c_r))
    return lambda n: (("none", 0.0),)


def part_error(case: Case, part: str, h: float, f: float, distance: float,
               dt: float | None = None, phase: bool = True) -> dict | None:
    """The predicted error of the whole path in ground part ``part`` (edge ``h``; ``dt``:
    the run's step, :func:`_schemes`; ``phase = False``: the peak error alone, the phase
    left NaN) on the case's soil element (:func:`soil_grid`); None for a part the case
    does not give."""
    from ..site import solid_material

    try:
        mat = solid_material(case, part)
    except KeyError:
        return None
    c_p, c_s = (float(v) for v in wave_speeds(mat["E"], mat["nu"], mat["rho"]))
    c_r = rayleigh_ratio(mat["nu"]) * c_s
    n_r = c_r / (f * h)
    wavelengths = distance * f / c_r
    grid = soil_grid(case)
    schemes = _schemes(case, c_p, c_r, f, mat["nu"], dt, grid)
    nu = float(mat["nu"])
    err, where = grid.worst(n_r, wavelengths, nu=nu, schemes=schemes(n_r))
    phase = (grid.worst(n_r, wavelengths, nu=nu, schemes=schemes(n_r), measure="phase")[0]
             if phase else float("nan"))
    return {"h": h, "c_s": c_s, "c_p": c_p, "c_r": c_r, "f": f, "dt": dt, "nu": nu,
            "epw": c_s / (f * h), "epw_rayleigh": n_r, "wavelengths": wavelengths,
            "error": err, "where": where, "phase": phase, "schemes": schemes,
            "order": grid.order}


def _mass(case: Case) -> str:
    return "lumped" if case["modal.lumped_mass"] else "consistent"


def _needed(case: Case, p: dict, limit: float, measure: str = "peak",
            order: int | None = None) -> float:
    """Elements per S wavelength for an error (or a phase error, ``measure = "phase"``)
    below ``limit`` in part ``p`` (inf: none), on the case's element or of ``order``."""
    ratio = p["epw_rayleigh"] / p["epw"]
    grid = soil_grid(case, order)
    own = grid.order == p["order"]
    schemes = p["schemes"] if own else _schemes(case, p["c_p"], p["c_r"], p["f"], p["nu"],
                                                p["dt"], grid)
    # the case's order misses the limit at its own size: search upwards from there; another
    # order may need fewer elements (:data:`_OTHER_ORDER_START`)
    lo = p["epw_rayleigh"] * (1.0 if own else _OTHER_ORDER_START)
    n = elements_needed(limit, p["wavelengths"], lo=lo, schemes=schemes, worst=grid.worst,
                        rtol=_ADVICE_RTOL[grid.order > 1], nu=p["nu"], measure=measure)
    return n / ratio


def _advice_for(case: Case, p: dict, limit: float, key: str, measure: str = "peak",
                advise: bool = True) -> tuple[str, float]:
    """The advice line for part ``p`` (:func:`_advice`) and the elements per S wavelength
    needed at the case's order (NaN: not computed, ``advise = False``; inf: none suffices);
    for a spectral soil the line adds what the next order needs."""
    if not advise:
        return _advice(math.nan, key, p["f"]), math.nan
    need = _needed(case, p, limit, measure)
    order = p["order"]
    if order == 1 or not np.isfinite(need):
        return _advice(need, key, p["f"], order), need
    text = _advice(need, key, p["f"], order, dofs=_dofs_per_m3(order, p, need))
    if order < MAX_ORDER:
        higher = _needed(case, p, limit, measure, order + 1)
        if np.isfinite(higher):
            text += (f"; or mesh.order = {order + 1} with mesh.elements_per_wavelength >= "
                     f"{_ceil(higher):g} ({_dofs_per_m3(order + 1, p, higher):.3g} DOFs per "
                     "m^3)")
    return text, need


def _dofs_per_m3(order: int, p: dict, epw: float) -> float:
    """DOFs per cubic metre of a grid of order ``order`` with ``epw`` elements per S
    wavelength at the band of part ``p`` (3 per GLL node, ``N^3`` nodes per element)."""
    h = p["c_s"] / (p["f"] * epw)
    return 3.0 * (order / h) ** 3


def _ceil(x: float) -> float:
    """Up to the next tenth (the advice's numbers)."""
    return float(np.ceil(x * 10) / 10)


def dispersion_report(quality: dict, case: Case, probes: Mapping[str, Any]) -> dict | None:
    """The dispersion check of a meshed model (None when ``mesh.wavelength_hz`` is 0).

    Returns
    -------
    dict or None
        ``frequency_hz``, ``probe``, ``distance_m``, ``track``, ``parts`` (per ground part:
        edge, c_S, elements per wavelength, wavelengths to the probe, error), ``part`` (the
        worst), ``error``, ``needed`` (elements per S wavelength for
        :data:`DISPERSION_TARGET`, when missed), ``line`` (the report line) and
        ``warnings``.

    Raises
    ------
    DispersionError
        When the band cannot be resolved at the farthest probe (the phase off by
        :data:`UNRESOLVED_PHASE` or more, or beyond the grid's cut-off), or the error reaches
        ``mesh.max_dispersion_error`` (> 0).
    """
    return band_report(quality, case, probes, case["mesh.wavelength_hz"],
                       "mesh.wavelength_hz")


def band_report(quality: dict, case: Case, probes: Mapping[str, Any], f: float, key: str,
                dt: float | None = None, refuse: bool = True, advise: bool = True
                ) -> dict | None:
    """:func:`dispersion_report` at the band ``f`` of the key ``key`` (``mesh.wavelength_hz``,
    or ``transient.f_max`` for the transient stage's own check at its step ``dt``); None
    when ``f`` is 0 or no ground part lies between the track and a probe.

    ``refuse = False``: an unresolved band is a warning, not a :class:`DispersionError`
    (the transient stage's default band, :func:`transient_band_check`); an error at or
    above ``mesh.max_dispersion_error`` is refused either way. ``advise = False``: the
    warnings leave out the elements per wavelength needed (each a root search over the
    grid's dispersion, seconds).
    """
    if f <= 0:
        return None
    name, distance, track = farthest_probe(case, probes)
    edges = quality.get("max_edge_per_soil_part", {})
    parts = {}
    for part in GROUND_PARTS:
        if part in edges and distance > 0:
            p = part_error(case, part, edges[part], f, distance, dt)
            if p is not None:
                parts[part] = p
    if not parts:
        return None
    worst = max(parts, key=lambda k: (parts[k]["error"], parts[k]["phase"]))
    p = parts[worst]
    out = {"frequency_hz": f, "probe": name, "distance_m": distance, "track": track,
           "part": worst, "error": p["error"], "phase_periods": _finite(p["phase"]),
           "warnings": [],
           "parts": {k: {**{key: v[key] for key in ("h", "c_s", "epw", "wavelengths", "error")},
                         "phase_periods": _finite(v["phase"])} for k, v in parts.items()}}
    out["key"] = key
    head = (f"numerical dispersion at the farthest probe, {name} ({distance:.3g} m from "
            f"track {track}'s centre line): at {key} = {f:g} Hz {worst} has "
            f"{_per_wavelength(p)} ({p['h']:.3g} m edges, c_S "
            f"{p['c_s']:.4g} m/s, {p['wavelengths']:.3g} Rayleigh wavelengths to the probe)")
    out["order"] = p["order"]
    out["line"] = (f"{head}: phase off by {p['phase']:.2g} period, predicted peak-velocity "
                   f"error {100 * p['error']:.3g} % ({soil_grid(case).mass}, "
                   f"{_where(p['where'])}; the whole path in the worst ground part, a "
                   "conservative bound)")
    if _refused(case, p, refuse):         # before the warning's advice (a root search)
        _refuse(case, out, p, refuse, advise)
    if p["error"] > DISPERSION_TARGET:
        advice, target = _advice_for(case, p, DISPERSION_TARGET, key, advise=advise)
        out["needed"] = target if np.isfinite(target) else None
        out["warnings"].append(
            f"{head}: predicted peak-velocity error {100 * p['error']:.3g} % > "
            f"{100 * DISPERSION_TARGET:g} %; {advice}")
    _refuse(case, out, p, refuse, advise)
    return out


def _where(where: str) -> str:
    """``"worst of axis, central"``, or the reason there is no worst (the GLL floor)."""
    return where if where.startswith("fewer than") else f"worst of {where}"


def _per_wavelength(p: dict) -> str:
    """``"3.2 elements per S wavelength"``, with the points of a spectral order."""
    text = f"{p['epw']:.3g} elements per S wavelength"
    if p["order"] > 1:
        text += f" (order {p['order']}: {p['order'] * p['epw']:.3g} points)"
    return text


def _refused(case: Case, p: dict, refuse: bool) -> bool:
    """Whether :func:`_refuse` raises for part ``p``."""
    limit = case["mesh.max_dispersion_error"]
    return (refuse and p["phase"] >= UNRESOLVED_PHASE) or (limit > 0 and p["error"] >= limit)


def _refuse(case: Case, out: dict, p: dict, refuse: bool = True, advise: bool = True
            ) -> None:
    """Refuse a band the mesh cannot resolve at the farthest probe (a phase error of
    :data:`UNRESOLVED_PHASE` or beyond the cut-off; only a warning with ``refuse =
    False``, added to ``out["warnings"]`` with ``out["unresolved"]``), or an error at or
    above ``mesh.max_dispersion_error`` (> 0)."""
    limit = case["mesh.max_dispersion_error"]
    key = out["key"]
    where = (f"{key} = {out['frequency_hz']:g}: at the farthest probe "
             f"{out['probe']} ({out['distance_m']:.3g} m from track {out['track']}) "
             f"{out['part']} has {_per_wavelength(p)}")
    unresolved = p["phase"] >= UNRESOLVED_PHASE
    if unresolved:
        off = (f"{p['phase']:.2g} period off" if np.isfinite(p["phase"]) else
               "beyond the grid's cut-off" if p["order"] == 1 else
               f"beyond what the grid resolves: {p['order'] * p['epw_rayleigh']:.2g} points "
               f"per Rayleigh wavelength, fewer than {MIN_POINTS_PER_WAVELENGTH:g}")
        text = (f"{where}: the mesh cannot resolve the band there (the wave arrives {off}; "
                f"allowed: less than {UNRESOLVED_PHASE:g} period); "
                f"{_advice_for(case, p, UNRESOLVED_PHASE, key, 'phase', advise)[0]}")
        if refuse:
            raise DispersionError(text)
    if limit > 0 and p["error"] >= limit:
        raise DispersionError(
            f"{where}: predicted peak-velocity error {100 * p['error']:.3g} % >= "
            f"mesh.max_dispersion_error = {limit:g}; "
            f"{_advice_for(case, p, limit, key, advise=advise or refuse)[0]}, or raise "
            "mesh.max_dispersion_error (0: no limit)")
    if unresolved:
        out["unresolved"] = True
        out["warnings"].append(text)


def transient_band_check(quality: dict, case: Case, probes: Mapping[str, Any],
                         dt: float) -> dict | None:
    """The ``transient`` stage's check at its own band, ``transient.f_max``, for its mass
    (``modal.lumped_mass``) and step ``dt`` (:func:`band_report`): the line, the warnings
    (an unresolved band is one: the default band of 80 Hz would refuse every run of a
    mesh sized for a lower band; ``mesh.wavelength_hz = transient.f_max`` refuses it) and
    ``resolved_up_to_hz``, the highest frequency whose predicted error at the farthest
    probe is at most :data:`DISPERSION_TARGET` (:func:`resolved_band`): what the run
    resolves, reported instead of ``transient.f_max``. None without a ground part between
    the track and a probe. An error at or above ``mesh.max_dispersion_error`` (> 0) is
    refused, as by the mesh check.
    """
    f_max = case["transient.f_max"]
    out = band_report(quality, case, probes, f_max, "transient.f_max", dt, refuse=False,
                      advise=False)
    if out is None:
        return None
    out["resolved_up_to_hz"] = (f_max if out["error"] <= DISPERSION_TARGET else
                                resolved_band(quality, case, probes, f_max, dt))
    return out


def resolved_band(quality: dict, case: Case, probes: Mapping[str, Any], f_max: float,
                  dt: float | None = None) -> float:
    """The highest one-third-octave nominal centre from 1 Hz up to ``f_max`` at which the
    predicted peak-velocity error at the farthest probe (the worst ground part) is at most
    :data:`DISPERSION_TARGET`, ``f_max`` itself when it is resolved, 0 when not even 1 Hz
    is (the bands the assessment reports, :func:`~railvib_hpc.assess.weighting.
    third_octave_bands`; the error grows with the frequency, so a binary search over
    them: five evaluations for 1-80 Hz)."""
    _, distance, _ = farthest_probe(case, probes)
    edges = quality.get("max_edge_per_soil_part", {})

    def resolved(f: float) -> bool:
        errs = [p["error"] for part in GROUND_PARTS if part in edges
                for p in [part_error(case, part, edges[part], f, distance, dt, False)]
                if p is not None]
        return max(errs, default=0.0) <= DISPERSION_TARGET

    candidates = third_octave_centres(f_max)
    if f_max not in candidates:
        candidates.append(float(f_max))
    lo, hi = -1, len(candidates)          # candidates[lo] resolved, candidates[hi] not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if resolved(candidates[mid]) else (lo, mid)
    return candidates[lo] if lo >= 0 else 0.0


def third_octave_centres(f_max: float) -> list[float]:
    """The nominal one-third-octave centres from 1 Hz up to ``f_max`` (ISO 266, the bands of
    :func:`~railvib_hpc.assess.weighting.third_octave_bands`).

    >>> third_octave_centres(5.0)
    [1.0, 1.25, 1.6, 2.0, 2.5, 3.15, 4.0, 5.0]
    """
    out, decade = [], 1.0
    while decade <= f_max * (1 + 1e-9):
        out += [round(m * decade, 6) for m in THIRD_OCTAVE_MANTISSAS
                if m * decade <= f_max * (1 + 1e-9)]
        decade *= 10.0
    return out


def _finite(x: float) -> float | None:
    """JSON-safe: None for inf."""
    return float(x) if np.isfinite(x) else None


def _advice(need: float, key: str = "mesh.wavelength_hz", f: float = 0.0, order: int = 1,
            dofs: float | None = None) -> str:
    """What makes the error small enough (``key``: the band's key, ``f`` its value; NaN
    ``need``: not computed; ``order``: the soil's, whose points per wavelength and DOFs per
    cubic metre ``dofs`` the advice adds for a spectral soil)."""
    if math.isnan(need):
        return (f"mesh with mesh.wavelength_hz = {f:g} and enough "
                f"mesh.elements_per_wavelength, or lower {key}")
    if np.isfinite(need):
        per = f"mesh.elements_per_wavelength >= {_ceil(need):g}"
        if order > 1:
            per += (f" (order {order}: {order * _ceil(need):.3g} points per S wavelength, "
                    f"{dofs:.3g} DOFs per m^3)")
        if key == "mesh.wavelength_hz":
            return f"raise {per.replace('>=', 'to >=', 1)} or lower mesh.wavelength_hz"
        return f"mesh with mesh.wavelength_hz = {f:g} and {per}, or lower {key}"
    return ("no element size suffices at this time step (the time scheme's own error): "
            f"lower transient.dt or raise transient.steps_per_period, or lower {key}")
