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
  the grid's own Rayleigh relation (:mod:`railvib_hpc.fem.dispersion_rayleigh`, checked
  against FE runs within 2.5 %) in the worse of a grid axis and a face diagonal (the
  diagonal, 1.8 times the axis's lag for the lumped mass). The bulk S relation at the
  Rayleigh wavelength, the check's proxy before, gave 9-11 % less lag;
* the error is the harmonic bound of :func:`~railvib_hpc.fem.dispersion.peak_velocity_error`
  at the band's top frequency, the larger of the semidiscretisation (the modal path, and a
  step tending to 0) and the transient engine at its largest step (``transient.dt`` or the
  automatic step's bound ``1 / (transient.steps_per_period transient.f_max)`` for the
  direct engine; for the explicit ones the soil grid's own limit, 0.9 of its critical step,
  which only lowers the lumped mass's lag): the time scheme's error is monotone in the step
  and of the opposite sign, so the worst lies at one of the two ends.

The check runs after meshing, with the measured edges, and before ``mesh.h5`` is written;
on a reused mesh it runs again (``output.probes`` and the limits are not mesh inputs).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np

from ..config import Case
from ..constants import THIRD_OCTAVE_MANTISSAS
from ..errors import MeshError
from ..fem.boundary import wave_speeds
from ..fem.dispersion import critical_courant, elements_needed
from ..fem.dispersion_rayleigh import worst_surface_error
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
#: The ground parts a wave crosses on its way to the probes.
GROUND_PARTS = ("subgrade", *SOIL_LAYER_PARTS)
#: Engines whose soil is integrated with central differences and the lumped mass (read
#: from the engines' declarations, :data:`railvib_hpc.time_engines.ENGINES`).
EXPLICIT_ENGINES = EngineNames(lambda d: d.soil_scheme == "central")


class DispersionError(MeshError):
    """A band the mesh cannot resolve at the farthest probe (``mesh.max_dispersion_error``)."""


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
             dt: float | None = None) -> Callable[[float], tuple[tuple[str, float], ...]]:
    """The ``(scheme, courant)`` ends of the step range, as a function of the elements per
    Rayleigh wavelength ``n`` (the element edge is ``c_R / (f n)``); ``dt``: the run's own
    step (the transient stage's check), else its bound from the case."""
    scheme = declaration(case["transient.engine"]).soil_scheme
    if scheme == "central":
        cc = EXPLICIT_STEP_SAFETY * critical_courant(nu, case["modal.hex_formulation"])
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
    left NaN); None for a part the case does not give."""
    from ..site import solid_material

    try:
        mat = solid_material(case, part)
    except KeyError:
        return None
    c_p, c_s = (float(v) for v in wave_speeds(mat["E"], mat["nu"], mat["rho"]))
    c_r = rayleigh_ratio(mat["nu"]) * c_s
    n_r = c_r / (f * h)
    wavelengths = distance * f / c_r
    schemes = _schemes(case, c_p, c_r, f, mat["nu"], dt)
    args = (n_r, wavelengths, mat["nu"], _mass(case), schemes(n_r), case["transient.rho_inf"],
            case["modal.hex_formulation"])
    err, where = worst_surface_error(*args)
    phase = worst_surface_error(*args, measure="phase")[0] if phase else float("nan")
    return {"h": h, "c_s": c_s, "nu": float(mat["nu"]), "epw": c_s / (f * h),
            "epw_rayleigh": n_r, "wavelengths": wavelengths, "error": err, "where": where,
            "phase": phase, "schemes": schemes}


def _mass(case: Case) -> str:
    return "lumped" if case["modal.lumped_mass"] else "consistent"


def _needed(case: Case, p: dict, limit: float, measure: str = "peak") -> float:
    """Elements per S wavelength for an error (or a phase error, ``measure = "phase"``)
    below ``limit`` in part ``p`` (inf: none)."""
    ratio = p["epw_rayleigh"] / p["epw"]
    n = elements_needed(limit, p["wavelengths"], lo=p["epw_rayleigh"], schemes=p["schemes"],
                        worst=worst_surface_error,
                        nu=p["nu"], mass=_mass(case), rho_inf=case["transient.rho_inf"],
                        formulation=case["modal.hex_formulation"], measure=measure)
    return n / ratio


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
            f"{p['epw']:.3g} elements per S wavelength ({p['h']:.3g} m edges, c_S "
            f"{p['c_s']:.4g} m/s, {p['wavelengths']:.3g} Rayleigh wavelengths to the probe)")
    out["line"] = (f"{head}: phase off by {p['phase']:.2g} period, predicted peak-velocity "
                   f"error {100 * p['error']:.3g} % ({_mass(case)} mass, worst of "
                   f"{p['where']}; the whole path in the worst ground part, a conservative "
                   "bound)")
    if p["error"] > DISPERSION_TARGET:
        target = _needed(case, p, DISPERSION_TARGET) if advise else math.nan
        out["needed"] = target if np.isfinite(target) else None
        out["warnings"].append(
            f"{head}: predicted peak-velocity error {100 * p['error']:.3g} % > "
            f"{100 * DISPERSION_TARGET:g} %; {_advice(target, key, f)}")
    _refuse(case, out, p, refuse, advise)
    return out


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
             f"{out['part']} has {p['epw']:.3g} elements per S wavelength")
    unresolved = p["phase"] >= UNRESOLVED_PHASE
    if unresolved:
        off = ("beyond the grid's cut-off" if not np.isfinite(p["phase"]) else
               f"{p['phase']:.2g} period off")
        need = _needed(case, p, UNRESOLVED_PHASE, "phase") if advise else math.nan
        text = (f"{where}: the mesh cannot resolve the band there (the wave arrives {off}; "
                f"allowed: less than {UNRESOLVED_PHASE:g} period); "
                f"{_advice(need, key, out['frequency_hz'])}")
        if refuse:
            raise DispersionError(text)
    if limit > 0 and p["error"] >= limit:
        need = _needed(case, p, limit) if advise or refuse else math.nan
        raise DispersionError(
            f"{where}: predicted peak-velocity error {100 * p['error']:.3g} % >= "
            f"mesh.max_dispersion_error = {limit:g}; "
            f"{_advice(need, key, out['frequency_hz'])}, or raise "
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


def _advice(need: float, key: str = "mesh.wavelength_hz", f: float = 0.0) -> str:
    """What makes the error small enough (``key``: the band's key, ``f`` its value; NaN
    ``need``: not computed)."""
    if math.isnan(need):
        return (f"mesh with mesh.wavelength_hz = {f:g} and enough "
                f"mesh.elements_per_wavelength, or lower {key}")
    if np.isfinite(need):
        per = f"mesh.elements_per_wavelength >= {np.ceil(need * 10) / 10:g}"
        if key == "mesh.wavelength_hz":
            return f"raise {per.replace('>=', 'to >=')} or lower mesh.wavelength_hz"
        return f"mesh with mesh.wavelength_hz = {f:g} and {per}, or lower {key}"
    return ("no element size suffices at this time step (the time scheme's own error): "
            f"lower transient.dt or raise transient.steps_per_period, or lower {key}")
