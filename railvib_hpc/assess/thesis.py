"""Comparison with the thesis: every row with the number that explains the difference.

The thesis (../shared/reference/thesis.md; benchmarks.md section 2) reports a model size,
a mode range, peak building accelerations and displacements, and wave arrivals. This
module puts this project's values next to them and explains each difference with a
number computed from the run (``docs/thesis.md`` has the longer story):

* model: the thesis layout reproduces Appendix B's element counts exactly; its printed
  node count (63,884, Appendix C) does not follow from them;
* sections: BEAM188 takes its section from ``SECDATA`` (:mod:`railvib_hpc.sections`), not
  from Table I;
* modes: 300 modes end where this model's spectrum puts them; Weyl's law for the soil box,
  ``N(f) = 4 pi / 3 V f^3 (1 / c_P^3 + 2 / c_S^3)``, and the modes-per-band scaling of the
  computed spectrum (``N ~ f^3``) give the count below the thesis's 57.87 Hz band;
* first frequency: modes 1-2 are the building's sway (kinetic energy share in the
  concrete, computed here with the consistent mass);
* accelerations: the start of the run (the thesis drops its wheelset from an unspecified
  height) and the ``q / omega`` scaling of its Appendix C post-processing (the same scaling
  applied to this run's modal accelerations gives the number shown);
* wave arrivals: on the thesis's clock (t = 0 with the wheel at x = 0; the flexible rail
  is entered at ``x1 / v``) at the far end of the track-side basement wall
  (``basement_wall_far``), 20.2 m from the entry point;
* reflection study and Table II: which of the thesis's models and readings correspond to
  which settings here.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..config import Case
from ..io.files import MBS_H5, MODES_H5
from ..io.formats.mbs import MbsFile
from ..problem import Problem
from ..site import track_lift

#: What the thesis reports, with where (thesis.md / benchmarks.md section 2).
THESIS = {
    "slab1_vertical_acceleration": 0.060,        # §6.5, Fig. 29
    "slab2_vertical_acceleration": 0.045,        # §6.5, Fig. 30
    "floor1_total_acceleration": 0.041,          # §6.9, Fig. 55
    "floor2_total_acceleration": 0.052,          # §6.9, Fig. 54
    "building_max_longitudinal_displacement": 0.528e-5,   # §6.3
    "building_max_transverse_displacement": 0.283e-5,     # §6.3
    "p_wave_arrival_basement_wall": 0.16,        # §6.6.1, thesis clock
    "s_wave_arrival_basement_wall": 0.20,        # §6.6.2, thesis clock
}
#: Appendix B element ranges: hexahedra per part group.
THESIS_HEXES = {"ballast": 2688, "subballast": 2688, "subgrade": 12288 + 19968,
                "concrete": 4248}
#: Appendix C: ``NN=63884`` nodes; §3: 300 modes, 9.56-57.87 Hz.
THESIS_NODES = 63884
#: Nodes of the conforming mesh with Appendix B's element counts (``mesh.layout = "thesis"``
#: at refinement 1; tests/mesh/test_mesh_model.py).
THESIS_LAYOUT_NODES = 51359
THESIS_N_MODES = 300
THESIS_F1_HZ = 9.56
THESIS_BAND_HZ = 57.87
#: §6.6: distance from the entry of the flexible rail to the basement wall [m].
THESIS_WAVE_DISTANCE = 20.2
#: Table I's rail section (the ``table1`` preset) for the sections row.
TABLE1_RAIL = {"area": 64.5e-4, "iyy": 2010e-8}
_CONCRETE = ("footing", "column", "beam", "slab", "wall")


def weyl_count(case: Case, f_hz: float) -> float:
    """Weyl's estimate of the number of modes below ``f_hz`` of the case's soil box.

    ``N(f) = (4 pi / 3) V f^3 (1 / c_P^3 + 2 / c_S^3)`` with the box volume ``V`` (layout
    bounds, top at ground level) and the subgrade wave speeds (asymptotic count of an
    elastic body; the building and embankment add little volume).
    """
    from ..mesh.layout import build_layout
    from .waves import wave_speeds

    x0, x1, y0, y1, z0, z1 = build_layout(case).bounds
    c_p, c_s = wave_speeds(Problem.from_case(case))
    volume = (x1 - x0) * (y1 - y0) * (z1 - z0)
    return 4.0 * math.pi / 3.0 * volume * f_hz**3 * (1.0 / c_p**3 + 2.0 / c_s**3)


def concrete_energy_shares(modes_path: Path, modes: int = 2) -> list[float]:
    """Kinetic-energy share of the concrete building in the first ``modes`` modes.

    ``phi^T M_c phi`` with the consistent mass ``M_c`` of the building's hexahedra; the
    modes are mass-normalised (``phi^T M phi = 1``), so this is the share directly. Empty
    when the model has no building (a user mesh of the track and soil only).
    """
    import h5py

    from ..fem.hex8 import hex8_mass
    from ..schema import PART_ID

    with h5py.File(modes_path, "r") as f:
        pts = f["mesh/points"][()]
        hexes, part = f["mesh/hexes"][()], f["mesh/hex_part"][()]
        conc = hexes[np.isin(part, [PART_ID[p] for p in _CONCRETE])]
        nodes = np.unique(conc)
        if nodes.size == 0:
            return []
        lo, hi = int(nodes.min()), int(nodes.max()) + 1
        phi = f["modes/translation"][:modes, lo:hi, :]
    rho = _concrete_density(modes_path)
    m_e = hex8_mass(pts[conc], rho)                          # (e, 24, 24)
    shares = []
    for k in range(phi.shape[0]):
        u = phi[k][conc - lo].reshape(len(conc), 24)          # node-major ux uy uz
        shares.append(float(np.einsum("ei,eij,ej->", u, m_e, u)))
    return shares


def _concrete_density(modes_path: Path) -> float:
    import h5py
    import tomllib

    with h5py.File(modes_path, "r") as f:
        text = f.attrs.get("case_toml", "")
    try:
        return float(tomllib.loads(text)["materials"]["concrete"]["rho"])
    except (tomllib.TOMLDecodeError, KeyError, TypeError):
        from ..schema import SCHEMA

        return float(SCHEMA["materials"]["concrete"]["rho"].default)


def appendix_c_peaks(modes_path: Path, mbs_path: Path, probes: dict[str, np.ndarray]
                     ) -> dict[str, float]:
    """Peak vertical "acceleration" of probes with the thesis's Appendix C scaling.

    Appendix C divides every modal coordinate read from SAMS by its circular frequency
    (``q(:,i)=q(:,i)/Omeg(i)``) before multiplying by the mode shapes. Applied to this
    run's modal accelerations: ``sum_i phi_i(probe) q''_i / omega_i`` (units m/s if
    ``q''`` is a modal acceleration: the scaling is dimensionally inconsistent unless
    SAMS's coordinates were scaled by ``omega`` themselves, which the thesis does not say).
    """
    from ..reconstruct.probes import probe_modes

    qdd, omega = MbsFile(mbs_path).modal_accelerations()
    names = list(probes)
    coords = np.array([probes[n] for n in names])
    phi, _, _ = probe_modes(modes_path, coords, qdd.shape[1], names)
    scaled = qdd / omega[None, :]
    return {n: float(np.abs(scaled @ phi[i][:, 2]).max()) for i, n in enumerate(names)}


def _row(quantity: str, thesis: str, railvib: str, explanation: str) -> dict:
    return {"quantity": quantity, "thesis": thesis, "railvib": railvib,
            "explanation": explanation}


def thesis_rows(case: Case, out_dir: Path, hist: dict, ours: dict,
                arrival: dict | None, modal: bool = True) -> list[dict]:
    """The rows of the thesis comparison (see the module notes).

    Parameters
    ----------
    case
        The assessed case.
    out_dir
        Folder with ``modes.h5`` and ``mbs.h5``.
    hist
        Probe histories (``probes.h5``).
    ours
        This run's values of the keys of :data:`THESIS` (None where not available).
    arrival
        Wave arrival at ``basement_wall_far`` on the thesis's clock (see
        :func:`thesis_clock_arrival`), or None.
    modal
        The numbers come from the modal solution (False: the full-order solution; the
        rows of the modes and of ``mbs.h5`` are left out even when the folder holds them).

    Returns
    -------
    list of dict
        ``quantity``, ``thesis``, ``railvib``, ``explanation`` (strings).
    """
    modes_path, mbs_path = out_dir / MODES_H5, out_dir / MBS_H5
    have_modes = modal and modes_path.exists()
    freq, counts, n_nodes = _read_modes(modes_path) if have_modes else (np.zeros(0), {}, 0)
    rows = _model_rows(case, counts, n_nodes) if counts else []
    rows.append(_section_row(case))
    if freq.size:
        rows += _mode_rows(case, freq, modes_path)
    c_peaks = {}
    if have_modes and mbs_path.exists():
        probes = {k: hist[k]["coords"] for k in ("slab1", "slab2") if k in hist}
        if probes:
            c_peaks = appendix_c_peaks(modes_path, mbs_path, probes)
    rows += _response_rows(case, ours, c_peaks)
    rows += _wave_rows(case, arrival)
    rows += _study_rows(case)
    return rows


def _read_modes(modes_path: Path) -> tuple[np.ndarray, dict[str, int], int]:
    """The frequencies, the hexahedra per part group of :data:`THESIS_HEXES` and the node
    count of ``modes.h5``."""
    import h5py

    from ..schema import PART_ID

    with h5py.File(modes_path, "r") as f:
        freq = f["modes/frequency_hz"][()]
        n_nodes = int(f["mesh/points"].shape[0])
        part = f["mesh/hex_part"][()]
    counts = {p: int(np.sum(part == PART_ID[p])) for p in ("ballast", "subballast",
                                                           "subgrade")}
    counts["concrete"] = int(np.sum(np.isin(part, [PART_ID[p] for p in _CONCRETE])))
    return freq, counts, n_nodes


def _model_rows(case: Case, counts: dict[str, int], n_nodes: int) -> list[dict]:
    """The model size: hexahedra per part group and nodes."""
    layout = case["mesh.layout"] if not case["mesh.file"] else f"file {case['mesh.file']}"
    same = all(counts[k] == v for k, v in THESIS_HEXES.items())
    ours_txt = ", ".join(f"{k} {counts[k]:,}" for k in THESIS_HEXES)
    return [
        _row("hexahedra (App. B element ranges)",
             ", ".join(f"{k} {v:,}" for k, v in THESIS_HEXES.items()),
             ours_txt + f" = {sum(counts.values()):,} (layout {layout}, refinement "
             f"{case['mesh.refinement']:g})",
             "identical: the thesis layout reproduces the APDL divisions" if same else
             f"mesh.layout = '{layout}' / refinement {case['mesh.refinement']:g}: "
             "mesh.layout = 'thesis' at refinement 1 gives the thesis's counts"),
        _row("nodes", f"{THESIS_NODES:,} (App. C: NN)", f"{n_nodes:,}",
             f"a conforming mesh with Appendix B's 41,880 hexahedra has "
             f"{THESIS_LAYOUT_NODES:,} nodes (this project, thesis layout); the printed count "
             f"is {THESIS_NODES - THESIS_LAYOUT_NODES:,} "
             "higher and follows from no documented mesh: compare element counts, not "
             "node counts"),
    ]


def _section_row(case: Case) -> dict:
    """The rail section: APDL ``SECDATA`` against Table I."""
    sec = case["sections.rail"]
    return _row(
        "rail section A / I_vert",
        "Table I: 64.5 cm² / 2010 cm⁴; APDL SECDATA: 79.1 cm² / 3956 cm⁴",
        f"{sec['area'] * 1e4:.1f} cm² / {sec['iyy'] * 1e8:.0f} cm⁴ (preset "
        f"{case['case.preset']})",
        "BEAM188 takes its section from SECTYPE/SECDATA, so the solved rail had "
        f"{79.13 / 64.5:.2f}x Table I's area and {3956 / 2010:.2f}x its bending stiffness "
        "(railvib_hpc.sections); case.preset = 'table1' uses Table I")


def _mode_rows(case: Case, freq: np.ndarray, modes_path: Path) -> list[dict]:
    """The mode count and band, and the first natural frequency."""
    n, f_top = freq.size, float(freq[-1])
    w_top = weyl_count(case, f_top)
    w_band = weyl_count(case, THESIS_BAND_HZ)
    scaled = n * (THESIS_BAND_HZ / f_top) ** 3
    band_n = int(np.sum(freq <= THESIS_BAND_HZ))
    covered = f_top >= THESIS_BAND_HZ
    rows = [_row(
        "modes: count and band",
        f"{THESIS_N_MODES} modes, {THESIS_F1_HZ}-{THESIS_BAND_HZ} Hz",
        f"{n} modes, {freq[0]:.2f}-{f_top:.2f} Hz"
        + (f"; {band_n} modes below {THESIS_BAND_HZ} Hz" if covered else ""),
        f"Weyl's law for this soil box gives {w_top:.0f} modes below {f_top:.1f} Hz "
        f"(computed: {n}) and {w_band:.0f} below {THESIS_BAND_HZ} Hz; scaling this "
        f"spectrum (N ~ f^3) gives {scaled:.0f}. 300 modes reach {THESIS_BAND_HZ} Hz "
        f"only with {w_band / THESIS_N_MODES:.1f}x fewer modes per band than the "
        "domain has: no documented variant does. The thesis's band: modal.f_max = "
        f"{THESIS_BAND_HZ} (railvib study thesis compares both)")]
    shares = concrete_energy_shares(modes_path, min(2, n))
    rows.append(_row(
        "first natural frequency", f"{THESIS_F1_HZ} Hz", f"{freq[0]:.3f} Hz"
        + (f" (mode 2: {freq[1]:.3f} Hz)" if n > 1 else ""),
        ("modes 1-2 are the building's sway: "
         + " and ".join(f"{100 * s:.0f} %" for s in shares)
         + " of their kinetic energy is in the concrete; the thesis's lowest mode is "
         f"very likely the same pair ({100 * (freq[0] / THESIS_F1_HZ - 1):+.1f} %)")
        if shares else "this model has no building, the thesis's lowest mode is the "
        "building's sway: not comparable"))
    return rows


def _response_rows(case: Case, ours: dict, c_peaks: dict[str, float]) -> list[dict]:
    """The peak accelerations of the slabs and floors and the building's displacements."""
    rows = []
    drop = case["vehicle.drop_height"]
    start = (f"a {drop * 1e3:g} mm drop" if drop > 0 else
             "a start at rest in static equilibrium")
    for key, label, probe in (("slab1_vertical_acceleration", "slab 1 vertical peak", "slab1"),
                              ("slab2_vertical_acceleration", "slab 2 vertical peak", "slab2")):
        val = ours.get(key)
        expl = (f"thesis / railvib = {THESIS[key] / val:.1f}; this run has {start}. The "
                "thesis drops its wheelset from an unspecified height: 0.01-0.1 mm already "
                "gives 24-48 kN contact peaks against 7.7 kN static (railvib study thesis: "
                "drop band)") if val else "no probe history"
        if probe in c_peaks and val:
            expl += (f". Appendix C divides every modal coordinate by omega before "
                     f"multiplying by the mode shapes: applied to this run that gives "
                     f"{c_peaks[probe]:.3g}, {val / c_peaks[probe]:.0f}x below the physical "
                     "value; unless SAMS wrote omega-scaled coordinates the thesis's plotted "
                     "accelerations are not Phi q'' (a possible inconsistency)")
        rows.append(_row(label, f"{THESIS[key]:g} m/s²", _fmt(val, "m/s²"), expl))
    for key, label in (("floor1_total_acceleration", "floor 1 total peak"),
                       ("floor2_total_acceleration", "floor 2 total peak")):
        val = ours.get(key)
        rows.append(_row(label, f"{THESIS[key]:g} m/s²", _fmt(val, "m/s²"),
                         f"thesis / railvib = {THESIS[key] / val:.1f}; same start and "
                         "post-processing "
                         "questions as the vertical peaks; the thesis's 0.005 g criterion is "
                         "a walking-vibration limit (reported for comparison)"
                         if val else "no probe history"))
    for key, label in (("building_max_longitudinal_displacement", "building max |u_x|"),
                       ("building_max_transverse_displacement", "building max |u_y|")):
        val = ours.get(key)
        rows.append(_row(label, f"{THESIS[key]:.3g} m", _fmt(val, "m"),
                         f"thesis / railvib = {THESIS[key] / val:.1f}; quasi-static response "
                         "to the wheel load, driven by the same start" if val else
                         "needs fields.h5 (railvib reconstruct)"))
    return rows


def _wave_rows(case: Case, arrival: dict | None) -> list[dict]:
    """The P- and S-wave arrivals at the far end of the basement wall, on the thesis's clock."""
    from .waves import wave_speeds

    c_p, c_s = wave_speeds(Problem.from_case(case))
    if arrival is None:
        return []
    rows = []
    for key, wave, c in (("p_wave_arrival_basement_wall", "P", c_p),
                         ("s_wave_arrival_basement_wall", "S", c_s)):
        t_an = arrival["t_entry"] + arrival["distance"] / c
        rows.append(_row(
            f"{wave}-wave arrival, far end of the basement wall",
            f"{THESIS[key]:g} s (20.2 m / {THESIS[key] - 0.1:.2f} s = "
            f"{THESIS_WAVE_DISTANCE / (THESIS[key] - 0.1):.0f} m/s)",
            f"analytic {t_an:.3f} s; detected onset {arrival['detected']:.3f} s",
            f"thesis clock: t = 0 with the wheel at x = 0, flexible rail entered at "
            f"{arrival['t_entry']:.3f} s; probe basement_wall_far (far end of the "
            f"track-side wall, mid-height) at r = {arrival['distance']:.2f} m from the "
            f"nearer rail at the entry (the thesis's 20.2 m: "
            f"{arrival['distance_far_rail']:.2f} m from the far rail to the base of that "
            f"wall end), c_{wave} = {c:.1f} m/s. A truncated modal "
            "basis is not causal (every mode responds at once): the detected onset is "
            "where the response first reaches "
            f"{100 * case['assessment.wave_threshold']:g} % of its peak"))
    return rows


def _study_rows(case: Case) -> list[dict]:
    """Which settings correspond to the thesis's reflection models and its Table II."""
    v = case["vehicle"]
    return [
        _row("reflection study (§6.7)",
             "Model 1: 3 m deep subgrade; Model 2: 5 m; Model 3: Model 2 + 2 m length, + 6 m "
             "width beyond the building; 'unchanged'",
             "railvib study reflection: model1 = 3 m (z0 raised 1.8 m), model2 = the APDL "
             "domain (4.8 m), model3 = model2 + 2 m each end + 6 m width, larger = reference",
             "labels follow the thesis's text; the APDL listing's 4.8 m subgrade is the "
             "thesis's '5 m' Model 2 (0.6 m and 2.4 m below the 2.4 m-deep building base)"),
        _row("Table II (wheelset)",
             "mass 1568 kg, Ixx 656, Iyy 168, Izz 13500 kg m²; K_l 25000, K_t 1000 'N.s/m', "
             "c_l 0, c_t blank",
             f"{v['wheelset_mass']:g} kg, Ixx {v['wheelset_roll_inertia']:g} kg m², "
             f"k {v['k_suspension']:g} N/m, c {v['c_suspension']:g} N s/m per side; static "
             f"wheel load {0.5 * v['wheelset_mass'] * 9.81 / 1e3:.2f} kN",
             "garbled table: read as vertical stiffness 25 kN/m with 1 kN s/m damping per "
             "side. Other reading (units shifted one row): k_l 25 kN/m, k_t 1 kN/m lateral, "
             "no damping (c_l = 0): --set vehicle.c_suspension=0 --set "
             "vehicle.k_lateral=1000. The static wheel load (7.69 kN) is the same in both"),
    ]


def _fmt(v: float | None, unit: str) -> str:
    return "–" if v is None else f"{v:.4g} {unit}"


def thesis_clock_arrival(case: Case, hist: dict, probe: str = "basement_wall_far"
                         ) -> dict | None:
    """Wave arrival at ``probe`` on the thesis's clock (t = 0 with the wheel at x = 0).

    Returns
    -------
    dict or None
        ``distance`` from the nearer rail where the wheels enter the flexible track
        (``x1``, rail height) to the probe [m] (the first arrival), ``distance_far_rail``
        from the far rail to the base of the probe's wall end (the thesis's 20.2 m),
        ``t_entry`` (entry into the flexible rail) and ``detected`` (first time the
        acceleration magnitude reaches ``assessment.wave_threshold`` of its peak after the
        entry) on the thesis's clock [s]; None without that probe.
    """
    from .waves import wave_arrival

    if probe not in hist:
        return None
    h = hist[probe]
    v, x0 = case["vehicle.speed"], case["vehicle.x_start"]
    shift = x0 / v                      # thesis clock = run clock + x_start / v
    t_entry = case["geometry.x1"] / v
    g = 0.5 * case["track.gauge"]
    z_rail = case["geometry.z4"] + track_lift(case)
    near = np.array([case["geometry.x1"], -g, z_rail])
    far = np.array([case["geometry.x1"], g, z_rail])
    base = np.array([h["coords"][0], h["coords"][1], case["geometry.zbb"]])
    detected = wave_arrival(h["t"] + shift, h["acceleration"], t_entry,
                            case["assessment.wave_threshold"])
    return {"distance": float(np.linalg.norm(np.asarray(h["coords"]) - near)),
            "distance_far_rail": float(np.linalg.norm(base - far)), "t_entry": t_entry,
            "detected": detected, "probe": probe}


def format_thesis_table(rows: list[dict]) -> str:
    """Plain-text table: quantity, thesis, railvib, then the explanation on its own line."""
    lines = ["comparison with the thesis (docs/thesis.md explains each row):"]
    for r in rows:
        lines.append(f"* {r['quantity']}")
        lines.append(f"    thesis:      {r['thesis']}")
        lines.append(f"    railvib:     {r['railvib']}")
        lines.append(f"    explanation: {r['explanation']}")
    return "\n".join(lines)
