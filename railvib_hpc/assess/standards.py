"""Limits of the vibration standards and the assessment of one probe against them.

Sources: ``/work/shared/reference/benchmarks.md`` section 4 (the project's reference
numbers); each choice beyond it is documented where it is made.

Standards (names accepted in ``standards``)
-------------------------------------------
The standards form a registry, :data:`STANDARDS` (name -> :class:`Standard`), filled by the
:func:`standard` decorator on each evaluation function below, under the names, titles and
order declared in :mod:`railvib_hpc.standards_registry` (below the case schema, which takes
its choices, ``assessment.standards``, from there). The registry gives :func:`assess_probe`
its dispatch and the report its order and titles; a new standard is one declaration and
one decorated function.

``"iso2631"``
    ISO 2631-2:2003 W_m weighting; the verdict compares the **MTVV** (maximum of the
    τ = 1 s running RMS of a_w) of each direction with the ISO 10137 / BS 6472 base curve
    value 0.005 m/s² (the 4–8 Hz plateau, which W_m's flat part matches) times the
    multiplier of the building use: critical 1, residential night 1.4, residential day 2
    (the lower end of the range 2–4, i.e. conservative), office 4, workshop 8. The MTVV is
    used rather than the record RMS because a train pass-by is transient and the record
    RMS depends on how much quiet time the record holds. a_w (record RMS), VDV and the
    crest factor are reported as well.
``"din4150-2"``
    KB_Fmax (KB-weighted velocity in mm/s, band 1–80 Hz, τ = 0.125 s) per direction,
    against the residential guide values A_u/A_o/A_r (day 0.15/3/0.07, night 0.1/0.2/0.05
    mm/s). Verdict: KB_Fmax ≤ A_u passes; KB_Fmax > A_o fails; in between KB_FTr ≤ A_r
    decides, with KB_FTr = KB_FTm·sqrt(N·T_e/T_r) for N pass-bys per assessment period
    (``din4150_2_events``; T_e = 30 s per cycle of the record, T_r = 16 h day / 8 h
    night). Without ``din4150_2_events`` that case is undetermined (``passed = None``). Only
    the residential row of DIN 4150-2 Table 1 is built in (the project reference lists
    only that row); it is used for every building use and the result says so.
``"din4150-3"``
    Peak particle velocity (mm/s) against the structural-damage limits. ``"foundation"``:
    each component against the frequency-dependent limit of its dominant frequency,
    piecewise linear between 1/10/50/100 Hz (line 1 commercial 20/20/40/50, line 2
    residential 5/5/15/20, line 3 sensitive 3/3/8/10 mm/s; the 1 Hz value below 1 Hz and
    the 100 Hz value above 100 Hz). ``"floor"``: vertical (z) component of a floor slab
    against 20 mm/s. ``"top_floor"``: horizontal components against the uppermost-floor
    values 40/15/8 mm/s (lines 1/2/3, all frequencies) and z against the slab value 20 mm/s.
``"fta"``
    FTA L_v = 20 log10(v_rms/1e-6 in/s) VdB of the maximum 1 s running RMS
    (exponential, τ = 1 s) velocity per direction: vibration-sensitive 65, residential
    72/75/80, institutional 75/78/83 VdB for frequent/occasional/infrequent events.
``"vc"``
    One-third-octave RMS velocity over the record (bands 1–80 Hz, each direction) against
    the VC curve of the building use: workshop 800, office 400, residential 200,
    critical 100 (ISO base curve ×1: 0.005 m/s²/(2π·8 Hz) = 99.5 µm/s), VC-A 50, VC-B 25,
    VC-C 12.5, VC-D 6.25, VC-E 3.12 µm/s, flat from 8 to 80 Hz. **Low frequencies
    (choice):** below 8 Hz the curve keeps the acceleration of its 8 Hz value (velocity
    limit ∝ 8/f), the 4–8 Hz plateau of the ISO base curve from which the
    workshop/office/residential curves derive, and the form Amick et al. (2005) give for
    VC-A (260 µg ≈ 50 µm/s·2π·8 Hz). ``vc_low_frequency="flat"`` keeps the flat value
    down to 1 Hz (the original, more conservative form).
``"thesis"``
    0.005 g = 0.049 m/s² on the peak acceleration of each direction and of the
    acceleration vector ("total"): an AISC/Murray walking-vibration limit about ten times
    the ISO base curve, reported for comparison with the thesis only. It never enters the
    overall verdict.

Results are plain JSON-serialisable dicts (floats, ints, strings, bools, ``None``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..constants import STANDARD_GRAVITY
from ..errors import UserError
from ..standards_registry import BUILDING_USES, DECLARED_STANDARDS, FTA_EVENTS, PERIODS
from . import metrics
from .weighting import BandSpectrum, third_octave_rms, weight_wm

__all__ = [
    "BUILDING_USES",
    "DIN4150_2_RESIDENTIAL",
    "DIN4150_3_FLOOR_VERTICAL",
    "DIN4150_3_LINES",
    "DIN4150_3_LOCATION_OF_ROLE",
    "DIN4150_3_TOP_FLOOR",
    "FTA_CRITERIA",
    "ISO_BASE_CURVE",
    "ISO_MULTIPLIERS",
    "STANDARDS",
    "THESIS_LIMIT",
    "VC_CURVES",
    "AssessInputError",
    "ProbeRecord",
    "Standard",
    "assess_probe",
    "din4150_2_guide_values",
    "din4150_3_limit",
    "format_table",
    "fta_limit",
    "iso_limit",
    "vc_curve",
    "vc_spectrum",
]

DIRECTIONS = ("x", "y", "z")

#: ISO 10137 / BS 6472 base curve [m/s² RMS] (vertical, 4–8 Hz).
ISO_BASE_CURVE = 0.005
#: Multipliers of the base curve per building use and period.
ISO_MULTIPLIERS: dict[str, dict[str, float]] = {
    "critical": {"day": 1.0, "night": 1.0},
    "residential": {"day": 2.0, "night": 1.4},
    "office": {"day": 4.0, "night": 4.0},
    "workshop": {"day": 8.0, "night": 8.0},
}

#: DIN 4150-2 residential guide values A_u, A_o, A_r [mm/s].
DIN4150_2_RESIDENTIAL: dict[str, dict[str, float]] = {
    "day": {"A_u": 0.15, "A_o": 3.0, "A_r": 0.07},
    "night": {"A_u": 0.1, "A_o": 0.2, "A_r": 0.05},
}
#: DIN 4150-2 assessment periods T_r [s].
DIN4150_2_PERIOD_S = {"day": 16 * 3600.0, "night": 8 * 3600.0}

#: DIN 4150-3 foundation limits [mm/s] at 1, 10, 50, 100 Hz (lines 1–3).
DIN4150_3_FREQ = (1.0, 10.0, 50.0, 100.0)
DIN4150_3_LINES: dict[str, tuple[float, float, float, float]] = {
    "commercial": (20.0, 20.0, 40.0, 50.0),
    "residential": (5.0, 5.0, 15.0, 20.0),
    "sensitive": (3.0, 3.0, 8.0, 10.0),
}
#: DIN 4150-3 uppermost floor, horizontal [mm/s], all frequencies.
DIN4150_3_TOP_FLOOR = {"commercial": 40.0, "residential": 15.0, "sensitive": 8.0}
#: DIN 4150-3 floor slabs, vertical [mm/s].
DIN4150_3_FLOOR_VERTICAL = 20.0

#: FTA criteria [VdB] per category and event frequency.
FTA_CRITERIA: dict[str, dict[str, float]] = {
    "sensitive": {"frequent": 65.0, "occasional": 65.0, "infrequent": 65.0},
    "residential": {"frequent": 72.0, "occasional": 75.0, "infrequent": 80.0},
    "institutional": {"frequent": 75.0, "occasional": 78.0, "infrequent": 83.0},
}

#: VC curves: flat one-third-octave RMS velocity [m/s] from 8 to 80 Hz.
VC_CURVES: dict[str, float] = {
    "workshop": 800e-6,
    "office": 400e-6,
    "residential": 200e-6,
    "critical": 100e-6,
    "VC-A": 50e-6,
    "VC-B": 25e-6,
    "VC-C": 12.5e-6,
    "VC-D": 6.25e-6,
    "VC-E": 3.12e-6,
}
VC_FMIN, VC_FMAX, VC_CORNER = 1.0, 80.0, 8.0

#: Thesis criterion 0.005 g [m/s², peak].
THESIS_LIMIT = 0.005 * STANDARD_GRAVITY

DIN4150_3_LOCATIONS = ("foundation", "floor", "top_floor")
#: DIN 4150-3 location of a probe by its role (railvib_hpc.schema.PROBE_ROLES): floor slabs
#: get the vertical floor limit; footings, walls and ground points (free-field points of the
#: probe lines too) the foundation limits.
DIN4150_3_LOCATION_OF_ROLE = {"floor": "floor", "wall": "foundation",
                              "foundation": "foundation", "ground": "foundation",
                              "free_field": "foundation"}
VC_LOW_FREQUENCY = ("constant_acceleration", "flat")


class AssessInputError(UserError, ValueError):
    """Invalid input of the assessment (a ``ValueError``; the CLI prints it without traceback)."""


def _bad(name: str, value: Any, allowed: str) -> AssessInputError:
    return AssessInputError(f"{name} = {value!r}: {allowed}")


def _choice(name: str, value: Any, allowed: Iterable[str]) -> str:
    allowed = tuple(allowed)
    if not isinstance(value, str) or value not in allowed:
        raise _bad(name, value, "allowed are " + ", ".join(repr(a) for a in allowed))
    return value


# --------------------------------------------------------------------------------------
# the registry


@dataclass(frozen=True)
class ProbeRecord:
    """One probe's checked histories, as every standard's evaluation receives them.

    Attributes
    ----------
    acceleration, velocity
        (nt, 3) histories [m/s², m/s], columns x, y, z (z vertical).
    fs
        Sample rate [Hz].
    duration
        Record length [s] (``nt / fs``).
    """

    acceleration: np.ndarray
    velocity: np.ndarray
    fs: float
    duration: float


@dataclass(frozen=True)
class Standard:
    """One entry of the standards registry.

    Attributes
    ----------
    name
        The name used in case files (``assessment.standards``) and results.
    title
        Heading of its block in results and reports.
    quantity
        The history it assesses: ``"acceleration"`` or ``"velocity"``.
    comparison_only
        Reported for comparison, never part of the overall verdict.
    evaluate
        ``evaluate(record, settings) -> dict``: the result block of one probe, from a
        :class:`ProbeRecord` and the resolved settings of :func:`assess_probe`
        (``settings["building_use"]``, ``"period"``, ...).
    """

    name: str
    title: str
    quantity: str
    comparison_only: bool
    evaluate: Callable[[ProbeRecord, Mapping[str, Any]], dict[str, Any]]


#: The registry: name -> :class:`Standard`, in report order (the order of registration).
STANDARDS: dict[str, Standard] = {}


def standard(name: str, title: str | None = None, quantity: str | None = None,
             comparison_only: bool | None = None):
    """Register the decorated ``evaluate(record, settings)`` function as a standard.

    Parameters
    ----------
    name
        The standard's name; one declared in
        :data:`railvib_hpc.standards_registry.DECLARED_STANDARDS` takes its title, quantity
        and ``comparison_only`` from there.
    title, quantity, comparison_only
        See :class:`Standard`; given, they replace the declared ones (required for a name
        not declared).

    Raises
    ------
    ValueError
        For a name registered twice, an undeclared name without title and quantity, or an
        unknown quantity.
    """
    if name in STANDARDS:
        raise ValueError(f"standard {name!r} is registered twice")
    declared = DECLARED_STANDARDS.get(name)
    if declared is None and (title is None or quantity is None):
        raise ValueError(f"standard {name!r} is not declared in railvib_hpc.standards_registry"
                         " and has no title and quantity")
    title = declared.title if title is None else title
    quantity = declared.quantity if quantity is None else quantity
    if comparison_only is None:
        comparison_only = declared is not None and declared.comparison_only
    if quantity not in ("acceleration", "velocity"):
        raise ValueError(f"standard {name!r}: quantity must be 'acceleration' or 'velocity'")

    def register(evaluate):
        STANDARDS[name] = Standard(name, title, quantity, comparison_only, evaluate)
        return evaluate

    return register


# --------------------------------------------------------------------------------------
# limits


def iso_limit(building_use: str = "residential", period: str = "day") -> float:
    """ISO 10137 / BS 6472 base-curve RMS limit [m/s²] for a building use and period.

    Parameters
    ----------
    building_use
        One of ``critical``, ``residential``, ``office``, ``workshop``.
    period
        ``day`` or ``night``.

    Returns
    -------
    float
        ``0.005 m/s² × multiplier``.
    """
    use = _choice("building_use", building_use, ISO_MULTIPLIERS)
    return ISO_BASE_CURVE * ISO_MULTIPLIERS[use][_choice("period", period, PERIODS)]


def din4150_2_guide_values(period: str = "day") -> dict[str, float]:
    """DIN 4150-2 residential guide values ``{"A_u", "A_o", "A_r"}`` [mm/s].

    Parameters
    ----------
    period
        ``day`` or ``night``.

    Returns
    -------
    dict
        A copy of the guide values.
    """
    return dict(DIN4150_2_RESIDENTIAL[_choice("period", period, PERIODS)])


def din4150_3_limit(f, structure: str = "residential") -> np.ndarray:
    """DIN 4150-3 foundation PPV limit [mm/s] at the dominant frequency ``f`` [Hz].

    Parameters
    ----------
    f
        Frequencies [Hz] (any shape, > 0).
    structure
        ``commercial`` (line 1), ``residential`` (line 2) or ``sensitive`` (line 3).

    Returns
    -------
    numpy.ndarray
        Limit, piecewise linear in f between 1, 10, 50 and 100 Hz; constant outside.
    """
    line = DIN4150_3_LINES[_choice("structure", structure, DIN4150_3_LINES)]
    return np.interp(np.asarray(f, dtype=float), DIN4150_3_FREQ, line)


def fta_limit(category: str = "residential", events: str = "frequent") -> float:
    """FTA ground-borne vibration criterion [VdB].

    Parameters
    ----------
    category
        ``sensitive`` (category 1), ``residential`` (2) or ``institutional`` (3).
    events
        ``frequent`` (> 70 events/day), ``occasional`` (30–70) or ``infrequent`` (< 30).

    Returns
    -------
    float
        Limit in VdB re 1e-6 in/s.
    """
    cat = _choice("category", category, FTA_CRITERIA)
    return FTA_CRITERIA[cat][_choice("events", events, FTA_EVENTS)]


def vc_curve(f, vc_class: str = "residential",
             low_frequency: str = "constant_acceleration") -> np.ndarray:
    """One-third-octave RMS velocity limit [m/s] of a VC curve at (nominal) frequencies ``f``.

    Parameters
    ----------
    f
        Band centre frequencies [Hz] (> 0).
    vc_class
        One of :data:`VC_CURVES`.
    low_frequency
        ``constant_acceleration`` (default: ``v·8/f`` below 8 Hz) or ``flat``.

    Returns
    -------
    numpy.ndarray
        Limit per frequency.
    """
    v = VC_CURVES[_choice("vc_class", vc_class, VC_CURVES)]
    _choice("vc_low_frequency", low_frequency, VC_LOW_FREQUENCY)
    f = np.asarray(f, dtype=float)
    if low_frequency == "flat":
        return np.full(f.shape, v)
    return v * np.maximum(1.0, VC_CORNER / f)


# --------------------------------------------------------------------------------------
# input checks


def _check_histories(t, acceleration, velocity) -> tuple[np.ndarray, np.ndarray, np.ndarray,
                                                         float]:
    try:
        t = np.asarray(t, dtype=float)
    except (TypeError, ValueError) as exc:
        raise _bad("t", type(t).__name__, "must be a 1-D array of times [s]") from exc
    if t.ndim != 1 or t.size < 4:
        raise _bad("t", f"array of shape {t.shape}", "must be 1-D with at least 4 samples")
    if not np.all(np.isfinite(t)):
        raise _bad("t", "array with NaN/inf", "all times must be finite")
    dt = np.diff(t)
    if np.any(dt <= 0.0):
        raise _bad("t", f"array with a non-increasing step at index {int(np.argmax(dt <= 0))}",
                   "times must be strictly increasing")
    step = (t[-1] - t[0]) / (t.size - 1)
    dev = float(np.max(np.abs(dt - step)) / step)
    if dev > 1e-5:
        raise _bad("t", f"array with steps varying by {dev:.2e} (relative)",
                   "the sampling must be uniform (relative step variation <= 1e-5); "
                   "resample the history first")
    out = []
    for name, arr in (("acceleration", acceleration), ("velocity", velocity)):
        try:
            arr = np.asarray(arr, dtype=float)
        except (TypeError, ValueError) as exc:
            raise _bad(name, type(arr).__name__, "must be a numeric (nt, 3) array") from exc
        if arr.shape != (t.size, 3):
            raise _bad(name, f"array of shape {arr.shape}",
                       f"must have shape (nt, 3) = ({t.size}, 3): x, y, z components [SI]")
        if not np.all(np.isfinite(arr)):
            raise _bad(name, "array with NaN/inf", "all values must be finite")
        out.append(arr)
    return t, out[0], out[1], 1.0 / step


def _check_standards(standards) -> list[str]:
    if isinstance(standards, str):
        standards = [standards]
    try:
        items = list(standards)
    except TypeError as exc:
        raise _bad("standards", standards, "must be a list of names from "
                   + ", ".join(STANDARDS)) from exc
    if not items:
        raise _bad("standards", standards, "must name at least one of " + ", ".join(STANDARDS))
    for s in items:
        _choice("standards entry", s, STANDARDS)
    if len(set(items)) != len(items):
        raise _bad("standards", standards, "each standard may appear only once")
    return [s for s in STANDARDS if s in items]


# --------------------------------------------------------------------------------------
# the per-standard evaluations


def _f(x) -> float | None:
    """A JSON-safe float (None for NaN/inf)."""
    x = float(x)
    return x if math.isfinite(x) else None


_AUTO = object()  # _entry: decide the verdict from value <= limit


def _entry(value, limit, *, passed: Any = _AUTO, **extra) -> dict[str, Any]:
    value, limit = _f(value), _f(limit)
    if passed is _AUTO:
        passed = None if value is None or limit is None else value <= limit
    util = value / limit if value is not None and limit else None
    return {"value": value, "limit": limit, "passed": None if passed is None else bool(passed),
            "utilisation": util, **extra}


def _block(name: str, metric: str, unit: str, directions: dict[str, dict],
           notes: list[str], **extra) -> dict[str, Any]:
    verdicts = [d["passed"] for d in directions.values()]
    if any(v is False for v in verdicts):
        passed = False
    elif any(v is None for v in verdicts):
        passed = None
    else:
        passed = True
    utils = [d["utilisation"] for d in directions.values() if d["utilisation"] is not None]
    return {"title": STANDARDS[name].title, "metric": metric, "unit": unit,
            "comparison_only": STANDARDS[name].comparison_only, "passed": passed,
            "utilisation": max(utils) if utils else None, "directions": directions,
            "notes": notes, **extra}


@standard("iso2631")
def _iso2631(r: ProbeRecord, s: Mapping[str, Any]) -> dict[str, Any]:
    a, fs, duration = r.acceleration, r.fs, r.duration
    use, period = s["building_use"], s["period"]
    aw = weight_wm(a, fs)
    mt = metrics.mtvv(aw, fs, metrics.TAU_SLOW)
    awr = metrics.rms(aw)
    vd = metrics.vdv(aw, fs)
    pk = metrics.peak(aw)
    limit = iso_limit(use, period)
    dirs = {d: _entry(mt[i], limit, a_w_rms=_f(awr[i]), vdv=_f(vd[i]),
                      crest_factor=_f(pk[i] / awr[i]) if awr[i] > 0 else None)
            for i, d in enumerate(DIRECTIONS)}
    notes = [f"limit = {ISO_BASE_CURVE} m/s² × {ISO_MULTIPLIERS[use][period]} "
             f"({use}, {period}); verdict on MTVV (τ = 1 s)"]
    if fs / 2 < 100.0:
        notes.append(f"Nyquist {fs / 2:.1f} Hz is below Wm's band limit 100 Hz: content above "
                     "it is not represented")
    if duration < 5 * metrics.TAU_SLOW:
        notes.append(f"record of {duration:.2f} s is shorter than 5 τ: the running RMS starts "
                     "from zero, MTVV may be underestimated for events near the start")
    return _block("iso2631", "MTVV of Wm-weighted acceleration (tau = 1 s)", "m/s^2", dirs,
                  notes, vdv_unit="m/s^1.75")


@standard("din4150-2")
def _din4150_2(r: ProbeRecord, s: Mapping[str, Any]) -> dict[str, Any]:
    v, fs = r.velocity, r.fs
    use, period, events = s["building_use"], s["period"], s["din4150_2_events"]
    v_mm = v * 1e3
    kbf = metrics.kb_f(v_mm, fs)
    kbmax = np.max(kbf, axis=0)
    ftm, n_cycles = metrics.kb_ftm(kbf, fs)
    g = din4150_2_guide_values(period)
    dirs = {}
    for i, d in enumerate(DIRECTIONS):
        kb_ftr = None
        if kbmax[i] <= g["A_u"]:
            passed = True
        elif kbmax[i] > g["A_o"]:
            passed = False
        elif events is not None:
            t_e = events * n_cycles * 30.0
            kb_ftr = float(ftm[i] * math.sqrt(t_e / DIN4150_2_PERIOD_S[period]))
            passed = kb_ftr <= g["A_r"]
        else:
            passed = None
        dirs[d] = _entry(kbmax[i], g["A_u"], passed=passed, A_o=g["A_o"], A_r=g["A_r"],
                         kb_ftm=_f(ftm[i]), kb_ftr=kb_ftr)
    notes = [f"residential guide values ({period}): A_u {g['A_u']}, A_o {g['A_o']}, "
             f"A_r {g['A_r']} mm/s (DIN 4150-2 Table 1, residential row)"]
    if use != "residential":
        notes.append(f"building use {use!r}: only the residential row of DIN 4150-2 is built in")
    if any(dirs[d]["passed"] is None for d in DIRECTIONS):
        notes.append("A_u < KB_Fmax <= A_o: the verdict needs KB_FTr; give din4150_2_events "
                     "(pass-bys per assessment period)")
    elif events is not None:
        notes.append(f"KB_FTr from {events} pass-bys × {n_cycles} × 30 s cycles in "
                     f"T_r = {DIN4150_2_PERIOD_S[period] / 3600:.0f} h")
    if fs / 2 < 80.0:
        notes.append(f"Nyquist {fs / 2:.1f} Hz is below the KB band limit 80 Hz")
    return _block("din4150-2", "KB_Fmax (KB-weighted velocity, tau = 0.125 s)", "mm/s", dirs,
                  notes, n_cycles=n_cycles, din4150_2_events=events)


@standard("din4150-3")
def _din4150_3(r: ProbeRecord, s: Mapping[str, Any]) -> dict[str, Any]:
    v, fs = r.velocity, r.fs
    structure, location = s["din4150_3_structure"], s["din4150_3_location"]
    ppv_method = s["ppv_frequency"]
    pk, freq = metrics.ppv(v * 1e3, fs, method=ppv_method)
    dirs: dict[str, dict] = {}
    if location == "foundation":
        for i, d in enumerate(DIRECTIONS):
            lim = din4150_3_limit(freq[i], structure) if np.isfinite(freq[i]) else \
                DIN4150_3_LINES[structure][0]
            dirs[d] = _entry(pk[i], lim, frequency_hz=_f(freq[i]))
        notes = [f"foundation, line {structure!r}: limit at the dominant frequency "
                 f"({ppv_method.replace('_', ' ')})"]
    else:
        if location == "top_floor":
            for i, d in enumerate(DIRECTIONS[:2]):
                dirs[d] = _entry(pk[i], DIN4150_3_TOP_FLOOR[structure],
                                 frequency_hz=_f(freq[i]))
        dirs["z"] = _entry(pk[2], DIN4150_3_FLOOR_VERTICAL, frequency_hz=_f(freq[2]))
        notes = [f"{location.replace('_', ' ')}: vertical slab limit "
                 f"{DIN4150_3_FLOOR_VERTICAL} mm/s"
                 + (f", horizontal uppermost-floor limit {DIN4150_3_TOP_FLOOR[structure]} mm/s "
                    f"(line {structure!r})" if location == "top_floor" else "")]
    return _block("din4150-3", "PPV (peak particle velocity)", "mm/s", dirs, notes,
                  structure=structure, location=location)


@standard("fta")
def _fta(r: ProbeRecord, s: Mapping[str, Any]) -> dict[str, Any]:
    v, fs, duration = r.velocity, r.fs, r.duration
    category, events = s["fta_category"], s["fta_events"]
    lv = metrics.fta_vdb(v, fs, tau=metrics.TAU_SLOW)
    lim = fta_limit(category, events)
    dirs = {}
    for i, d in enumerate(DIRECTIONS):
        val = _f(lv[i])  # -inf (no motion) -> None
        passed = bool(lv[i] <= lim)
        util = _f(10.0 ** ((lv[i] - lim) / 20.0))
        dirs[d] = {"value": val, "limit": lim, "passed": passed, "utilisation": util,
                   "margin_db": _f(lim - lv[i])}
    notes = [f"category {category!r}, {events} events: {lim:g} VdB re 1e-6 in/s; "
             "max of the exponential 1 s running RMS velocity"]
    if duration < 5 * metrics.TAU_SLOW:
        notes.append(f"record of {duration:.2f} s is shorter than 5 τ: the 1 s RMS may be "
                     "underestimated for events near the start")
    return _block("fta", "L_v of max 1 s running RMS velocity", "VdB", dirs, notes,
                  category=category, events=events)


def vc_spectrum(v, fs: float) -> BandSpectrum:
    """One-third-octave RMS velocity spectrum (1–80 Hz) used for the VC assessment.

    Parameters
    ----------
    v
        (nt, 3) velocity [m/s].
    fs
        Sample rate [Hz].

    Returns
    -------
    BandSpectrum
        RMS over the record per band and direction.
    """
    return third_octave_rms(v, fs, fmin=VC_FMIN, fmax=VC_FMAX, axis=0)


@standard("vc")
def _vc(r: ProbeRecord, s: Mapping[str, Any]) -> dict[str, Any]:
    v, fs = r.velocity, r.fs
    vc_class, low_frequency = s["vc_class"], s["vc_low_frequency"]
    spec = vc_spectrum(v, fs)
    nominal = spec.bands.nominal
    lim = vc_curve(nominal, vc_class, low_frequency)
    resolved = spec.n_bins > 0
    ratio = np.where(resolved[:, None], spec.rms / lim[:, None], np.nan)
    dirs = {}
    for i, d in enumerate(DIRECTIONS):
        if not resolved.any():
            dirs[d] = _entry(float("nan"), float("nan"))
            continue
        k = int(np.nanargmax(ratio[:, i]))
        dirs[d] = _entry(spec.rms[k, i], lim[k], governing_band_hz=float(nominal[k]))
    notes = [f"curve {vc_class!r} ({VC_CURVES[vc_class] * 1e6:g} µm/s flat 8–80 Hz; "
             f"below 8 Hz: {low_frequency.replace('_', ' ')}); RMS over the whole record"]
    empty = nominal[~resolved]
    if empty.size:
        notes.append("bands without FFT bins (record too short or above Nyquist), not "
                     "assessed: " + ", ".join(f"{f:g}" for f in empty) + " Hz")
    return _block("vc", "max one-third-octave RMS velocity / curve", "m/s", dirs, notes,
                  vc_class=vc_class, low_frequency=low_frequency,
                  bands={"nominal_hz": [float(f) for f in nominal],
                         "n_bins": [int(n) for n in spec.n_bins],
                         "limit": [float(x) for x in lim],
                         **{d: [float(x) for x in spec.rms[:, i]]
                            for i, d in enumerate(DIRECTIONS)}})


@standard("thesis")
def _thesis(r: ProbeRecord, s: Mapping[str, Any]) -> dict[str, Any]:
    a = r.acceleration
    pk = metrics.peak(a)
    total = float(np.max(np.linalg.norm(a, axis=1)))
    dirs = {d: _entry(pk[i], THESIS_LIMIT) for i, d in enumerate(DIRECTIONS)}
    dirs["total"] = _entry(total, THESIS_LIMIT)
    notes = ["0.005 g walking-vibration limit (AISC/Murray), about 10× the ISO base curve: "
             "for comparison with the thesis only, not a verdict"]
    return _block("thesis", "peak acceleration", "m/s^2", dirs, notes)


# --------------------------------------------------------------------------------------
# public entry points


if tuple(STANDARDS) != tuple(DECLARED_STANDARDS):
    raise ImportError("the standards registered here and those declared in "
                      f"railvib_hpc.standards_registry differ: {tuple(STANDARDS)} against "
                      f"{tuple(DECLARED_STANDARDS)}")


def assess_probe(t, acceleration, velocity, standards: Sequence[str] | None = None, *,
                 building_use: str = "residential", period: str = "day",
                 fta_events: str = "frequent", fta_category: str | None = None,
                 vc_class: str | None = None,
                 vc_low_frequency: str = "constant_acceleration",
                 din4150_3_structure: str | None = None,
                 din4150_3_location: str = "foundation",
                 din4150_2_events: int | None = None,
                 ppv_frequency: str = "zero_crossing") -> dict[str, Any]:
    """Assess one probe's response against vibration standards.

    Parameters
    ----------
    t
        (nt,) uniformly spaced times [s].
    acceleration, velocity
        (nt, 3) histories [m/s², m/s], columns x, y, z (z vertical).
    standards
        Names from the registry :data:`STANDARDS` (``iso2631``, ``din4150-2``,
        ``din4150-3``, ``fta``, ``vc``, ``thesis``); None: all of them.
    building_use
        ``critical``, ``residential``, ``office`` or ``workshop``: selects the ISO
        multiplier and (unless overridden) the FTA category, VC curve and DIN 4150-3 line.
    period
        ``day`` or ``night`` (ISO multiplier for residential, DIN 4150-2 guide values).
    fta_events
        ``frequent``, ``occasional`` or ``infrequent``.
    fta_category
        Override: ``sensitive``, ``residential`` or ``institutional``.
    vc_class
        Override of the VC curve (a key of :data:`VC_CURVES`, e.g. ``"VC-A"``).
    vc_low_frequency
        ``constant_acceleration`` (default) or ``flat`` below 8 Hz.
    din4150_3_structure
        Override: ``commercial``, ``residential`` or ``sensitive`` (lines 1–3).
    din4150_3_location
        ``foundation`` (default), ``floor`` or ``top_floor``.
    din4150_2_events
        Pass-bys per assessment period, for KB_FTr (``None``: not given).
    ppv_frequency
        ``zero_crossing`` (default) or ``spectrum``: dominant frequency of the PPV.

    Returns
    -------
    dict
        JSON-serialisable: ``record`` (samples, rate, duration), ``settings``,
        ``standards`` (per standard: ``title``, ``metric``, ``unit``, ``passed``,
        ``utilisation``, ``comparison_only``, ``notes`` and ``directions`` → per direction
        ``value``, ``limit``, ``passed``, ``utilisation`` and metric details) and
        ``passed`` (all assessed standards except comparison-only ones; ``None`` when a
        verdict is undetermined).

    Raises
    ------
    AssessInputError
        (a ``ValueError``) naming the argument, its value and what is allowed.
    """
    t, a, v, fs = _check_histories(t, acceleration, velocity)
    names = _check_standards(list(STANDARDS) if standards is None else standards)
    use = _choice("building_use", building_use, BUILDING_USES)
    period = _choice("period", period, PERIODS)
    fta_events = _choice("fta_events", fta_events, FTA_EVENTS)
    fta_category = _choice("fta_category", fta_category or BUILDING_USES[use]["fta"],
                           FTA_CRITERIA)
    vc_class = _choice("vc_class", vc_class or BUILDING_USES[use]["vc"], VC_CURVES)
    vc_low_frequency = _choice("vc_low_frequency", vc_low_frequency, VC_LOW_FREQUENCY)
    structure = _choice("din4150_3_structure",
                        din4150_3_structure or BUILDING_USES[use]["din4150-3"],
                        DIN4150_3_LINES)
    location = _choice("din4150_3_location", din4150_3_location, DIN4150_3_LOCATIONS)
    ppv_frequency = _choice("ppv_frequency", ppv_frequency, ("zero_crossing", "spectrum"))
    if din4150_2_events is not None and (
            isinstance(din4150_2_events, bool) or not isinstance(din4150_2_events, int | np.integer)
            or din4150_2_events < 1):
        raise _bad("din4150_2_events", din4150_2_events,
                   "must be None or a positive integer (pass-bys per assessment period)")
    events = None if din4150_2_events is None else int(din4150_2_events)
    duration = float(t[-1] - t[0] + 1.0 / fs)

    settings = {"standards": names, "building_use": use, "period": period,
                "fta_events": fta_events, "fta_category": fta_category,
                "vc_class": vc_class, "vc_low_frequency": vc_low_frequency,
                "din4150_3_structure": structure, "din4150_3_location": location,
                "din4150_2_events": events, "ppv_frequency": ppv_frequency}
    record = ProbeRecord(acceleration=a, velocity=v, fs=fs, duration=duration)
    blocks = {name: STANDARDS[name].evaluate(record, settings) for name in names}
    verdicts = [b["passed"] for b in blocks.values() if not b["comparison_only"]]
    if any(p is False for p in verdicts):
        overall = False
    elif any(p is None for p in verdicts) or not verdicts:
        overall = None
    else:
        overall = True
    return {
        "schema": "railvib_hpc.assess/1",
        "record": {"n_samples": int(t.size), "sample_rate_hz": fs, "duration_s": duration,
                   "t_start_s": float(t[0])},
        "settings": settings,
        "standards": blocks,
        "passed": overall,
    }


def _cell(block: Mapping[str, Any] | None) -> str:
    if block is None:
        return "-"
    util = block.get("utilisation")
    u = f"{util:.2f}" if util is not None else "n/a"
    passed = block.get("passed")
    if block.get("comparison_only"):
        word = "ok*" if passed else ("over*" if passed is False else "?*")
    else:
        word = "PASS" if passed else ("FAIL" if passed is False else "UNDET")
    return f"{word} {u}"


def format_table(results: Mapping[str, Mapping[str, Any]]) -> str:
    """A printable pass/fail table, probes × standards.

    Parameters
    ----------
    results
        Probe name → result of :func:`assess_probe`.

    Returns
    -------
    str
        Fixed-width table; each cell is the verdict and the utilisation (largest
        value/limit of the directions, ≤ 1 passes), followed by a legend.
    """
    if not isinstance(results, Mapping) or not results:
        raise _bad("results", results, "must be a non-empty mapping probe name -> result")
    names = [s for s in STANDARDS
             if any(s in r.get("standards", {}) for r in results.values())]
    header = ["probe", *names, "overall"]
    rows = []
    for probe, r in results.items():
        overall = r.get("passed")
        rows.append([str(probe), *(_cell(r["standards"].get(s)) for s in names),
                     "PASS" if overall else ("FAIL" if overall is False else "UNDET")])
    widths = [max(len(row[i]) for row in [header, *rows]) for i in range(len(header))]
    line = "  ".join("-" * w for w in widths)
    out = ["  ".join(h.ljust(w) for h, w in zip(header, widths)), line]
    out += ["  ".join(c.ljust(w) for c, w in zip(row, widths)) for row in rows]
    out.append("")
    out.append("cells: verdict and utilisation (largest value/limit over the directions; "
               "<= 1 passes). UNDET: verdict needs more input (see notes). * comparison "
               "only, not part of the overall verdict.")
    return "\n".join(out)
