"""The ``assess`` stage: probe histories -> standards, wave arrivals, thesis comparison, report.

Runs on rank 0 (numpy); every rank gets the summary or the error. Reads
``probes.h5`` (written by ``railvib reconstruct``) and ``mbs.h5`` (contact
forces for the report), evaluates every probe against the standards of
``[assessment]`` and writes ``assessment.json`` plus the report
(``report.md``, ``report.html``, ``report.json``, ``figures/*.png``).

In the folder of the full-order solution (``railvib transient``: its ``probes.h5`` was
written by that stage, :func:`solver_of`) it verifies and reads ``transient.h5`` and the
transient ``fields.h5`` and ``probes.h5`` instead of ``modes.h5``, ``mbs.h5`` and the
reconstruction; the report and ``assessment.json`` (``solver``) say which solver produced
the numbers.

DIN 4150-3 location per probe, from the role it carries (set where the probe is
defined: the mesh layout, ``output.probe_roles``): ``floor`` probes get the vertical
floor-slab limit, every other role (foundation, wall, ground) is assessed as a
foundation (:data:`railvib_hpc.assess.standards.DIN4150_3_LOCATION_OF_ROLE`).

Wave arrivals: the load enters the soil when the first wheel reaches the
flexible rail (``t_entry``); at a probe at distance ``r`` from that point the
P and S waves arrive at ``t_entry + r / c_P`` and ``t_entry + r / c_S`` (wave
speeds of the subgrade). The detected arrival is the first time after
``t_entry`` at which the acceleration magnitude exceeds
``assessment.wave_threshold`` times its peak; it is compared with both. A
truncated modal basis is not causal (each mode responds everywhere at once),
so the detected onset can precede the analytic arrival: the comparison shows
how well the modes represent wave propagation.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..config import Case
from ..io.atomic import write_json
from ..io.files import (
    ASSESSMENT_JSON,
    FIELDS_H5,
    MBS_H5,
    MODES_H5,
    PROBES_H5,
    REPORT_HTML,
    REPORT_JSON,
    REPORT_MD,
    STATIC_H5,
    TRANSIENT_FIELDS,
    TRANSIENT_H5,
    TRANSIENT_PROBES,
)
from ..io.formats.fields import FieldsFile
from ..io.formats.mbs import MbsFile, passage_inputs
from ..io.formats.probes import ProbesFileError, read_probes  # read_probes re-exported
from ..io.formats.transient import TransientFile
from ..io.products import ALL_KEYS, StageFile
from ..io.stage_outputs import AssessmentOutput
from ..io.stage_protocol import Stage, StageContext, StageRunner
from ..log import Reporter
from ..parallel import on_root
from ..problem import Problem
from ..site import line_probes, track_lift
from .thesis import THESIS  # what the thesis reports (re-exported; see .thesis)
from .waves import wave_arrival, wave_speeds  # re-exported

if TYPE_CHECKING:
    from mpi4py import MPI


#: The assessment's input errors: those of ``probes.h5`` (re-exported name).
AssessStageError = ProbesFileError


def _contact(out_dir: Path, solver: str):
    """Wheel positions and contact forces of ``mbs.h5``, or of the full-order solution's
    ``transient.h5``."""
    reader = (MbsFile(out_dir / MBS_H5) if solver != "transient"
              else TransientFile(out_dir / TRANSIENT_H5))
    return reader.contact() if reader.path.exists() else (None, None)


def _load_entry(case: Case) -> tuple[np.ndarray, float]:
    """Where and when the load enters the model, the origin of the wave arrivals: the first
    wheel on the flexible rail of track 1 (its left rail), or with ``track.count = 0`` the
    leading surface load on the soil's ground (``load.y``, ``geometry.z1``)."""
    if case["track.count"]:
        x_entry = case["geometry.x1"]
        t_entry = (x_entry - case["vehicle.x_start"]) / case["vehicle.speed"]
        return (np.array([x_entry, -0.5 * case["track.gauge"],
                          case["geometry.z4"] + track_lift(case)]), t_entry)
    x_entry = max(case["load.x_start"], case["geometry.x1"] - case["domain.extra_length"])
    t_entry = (x_entry - case["load.x_start"]) / case["load.speed"]
    return np.array([x_entry, case["load.y"], case["geometry.z1"]]), t_entry


def _thesis_comparison(hist: dict, fields_path: Path) -> dict:
    """Our values of the quantities the thesis reports."""
    out: dict[str, float | None] = {}
    for k, level in (("slab1", "1"), ("slab2", "2")):
        if k in hist:
            a = hist[k]["acceleration"]
            out[f"slab{level}_vertical_acceleration"] = float(np.abs(a[:, 2]).max())
            out[f"floor{level}_total_acceleration"] = float(np.linalg.norm(a, axis=1).max())
    out.update(_building_displacements(fields_path))
    return out


def _building_displacements(fields_path: Path) -> dict:
    """Max |ux| and |uy| over the building nodes in fields.h5 (streamed over time)."""
    from ..schema import BUILDING_PARTS, PART_ID

    if not fields_path.exists():
        return {}
    fields = FieldsFile(fields_path)
    if not fields.complete():
        return {}
    _, hexes, part = fields.mesh()
    ids = [PART_ID[p] for p in BUILDING_PARTS]
    nodes = np.unique(hexes[np.isin(part, ids)])
    if nodes.size == 0:                         # a mesh without the building (mesh.file)
        return {}
    ux = uy = 0.0
    for blk in fields.blocks("displacement", nodes, 64):
        ux = max(ux, float(np.abs(blk[..., 0]).max()))
        uy = max(uy, float(np.abs(blk[..., 1]).max()))
    return {"building_max_longitudinal_displacement": ux,
            "building_max_transverse_displacement": uy}


def peak_map(fields_path: Path, z_ground: float, png: Path) -> dict | None:
    """Peak velocity magnitude over time of the ground-surface and slab-top nodes: PNG + data.

    Streams ``/fields/velocity`` of ``fields.h5`` over blocks of steps. Ground
    nodes: ``z = z_ground`` (top of the subgrade); slab nodes: the top faces of
    the slabs. None when there is no complete ``fields.h5``.
    """
    import matplotlib

    from ..schema import PART_ID

    if not fields_path.exists():
        return None
    fields = FieldsFile(fields_path)
    if not fields.complete():
        return None
    pts, hexes, part = fields.mesh()
    slab_top = _slab_top_nodes(pts, hexes[part == PART_ID["slab"]])
    ground = np.flatnonzero(np.isclose(pts[:, 2], z_ground))
    nodes = np.unique(np.concatenate([ground, slab_top]))
    peak = np.zeros(nodes.size)
    for blk in fields.blocks("velocity", nodes, 32):
        peak = np.maximum(peak, np.linalg.norm(blk, axis=2).max(axis=0))
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import LogNorm

    fig, axes = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [2, 1]})
    on_ground = np.isin(nodes, ground)
    vmin = max(float(peak[peak > 0].min()) if (peak > 0).any() else 1e-12, 1e-3 * peak.max())
    norm = LogNorm(vmin=vmin, vmax=max(float(peak.max()), vmin * 10))
    for ax, sel, title in ((axes[0], on_ground, f"ground surface z = {z_ground:g} m"),
                           (axes[1], ~on_ground, "slab tops")):
        p = pts[nodes[sel]]
        sc = ax.scatter(p[:, 0], p[:, 1], c=np.maximum(peak[sel], vmin), s=6, norm=norm,
                        cmap="viridis")
        ax.set_aspect("equal")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(title)
    fig.colorbar(sc, ax=axes, label="peak velocity magnitude [m/s]")
    png.parent.mkdir(parents=True, exist_ok=True)
    from ..io.atomic import atomic_file

    with atomic_file(png) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
    return {"x": pts[nodes, 0].tolist(), "y": pts[nodes, 1].tolist(),
            "z": pts[nodes, 2].tolist(), "peak_velocity": peak.tolist()}


def _slab_top_nodes(pts: np.ndarray, slab_hexes: np.ndarray) -> np.ndarray:
    """Nodes on the top faces of the slabs (top of a slab hex, bottom of none)."""
    z = pts[slab_hexes, 2]
    top = slab_hexes[np.isclose(z, z.max(axis=1, keepdims=True))]
    bottom = slab_hexes[np.isclose(z, z.min(axis=1, keepdims=True))]
    return np.setdiff1d(np.unique(top), np.unique(bottom))


#: The files of the full-order solution the assessment rests on (table names).
TRANSIENT_INPUTS = (TRANSIENT_H5, TRANSIENT_FIELDS, TRANSIENT_PROBES)


def solver_of(out_dir: Path) -> str:
    """Which solver's results ``out_dir`` holds (rank 0): ``transient`` when its
    ``probes.h5`` was written by ``railvib transient`` (or, without a readable
    ``probes.h5``, when there is a ``transient.h5`` and no ``modes.h5``), else ``modal``."""
    from ..io.provenance import read_provenance

    probes = out_dir / PROBES_H5
    if probes.exists():
        try:
            return "transient" if read_provenance(probes).get("stage") == "transient" \
                else "modal"
        except (OSError, ValueError, KeyError):
            pass
    return "transient" if (out_dir / TRANSIENT_H5).exists() \
        and not (out_dir / MODES_H5).exists() else "modal"


def verify_chain(ctx: StageContext, solver: str = "modal") -> dict[str, str]:
    """Verify every file the assessment rests on for the context's case (rank 0):
    ``modes.h5`` (``static.h5``), ``mbs.h5``, ``fields.h5``, ``probes.h5`` (with ``solver =
    "transient"``: ``transient.h5`` and the transient ``fields.h5``, ``probes.h5``) must
    exist, be complete, be computed with the case's values from each other, be unchanged
    and sound.

    Returns
    -------
    dict
        Their content digests by file name.

    Raises
    ------
    StaleInputError
        For the first file (in pipeline order) that is not, naming what differs and the
        command to run.
    """
    from ..io.products import spec

    if solver == "transient":
        digests = dict(ctx.input("transient", TRANSIENT_INPUTS).digests)
    else:              # the modal solution: the modes, the passage, their reconstruction
        passage = passage_inputs(ctx.out_dir)
        digests = {**ctx.input("modal", passage[:-1]).digests,
                   **ctx.input("mbs", passage[-1:]).digests,
                   **ctx.input("reconstruct", (FIELDS_H5, PROBES_H5)).digests}
    return {spec(n).filename: sha for n, sha in digests.items()}


def assess_case(ctx: StageContext) -> dict:
    """Assess every probe of ``probes.h5`` in the context's folder; write the report; return
    the summary (rank 0).

    Nothing is labelled with the case before :func:`verify_chain` confirmed that every
    input file belongs to it.
    """
    from .floors import floor_summary, format_floor_table
    from .free_field import format_free_field, free_field_summary
    from .report import write_report
    from .standards import DIN4150_3_LOCATION_OF_ROLE, assess_probe, format_table
    from .thesis import format_thesis_table, thesis_clock_arrival, thesis_rows

    case, out_dir, rep = ctx.case, ctx.out_dir, ctx.rep
    solver = solver_of(out_dir)
    upstream = verify_chain(ctx, solver)
    ctx.discard(out_dir / ASSESSMENT_JSON)
    hist = read_probes(out_dir / PROBES_H5)
    a = case["assessment"]
    results = {}
    for name, h in hist.items():
        location = DIN4150_3_LOCATION_OF_ROLE[h["role"]]
        results[name] = assess_probe(
            h["t"], h["acceleration"], h["velocity"], a["standards"],
            building_use=a["building_use"], period=a["period"], fta_events=a["fta_events"],
            din4150_3_location=location,
            din4150_2_events=a["din4150_2_events"] or None)
    # wave arrivals relative to the first wheel entering the flexible rail (or the surface
    # load entering the soil)
    c_p, c_s = wave_speeds(Problem.from_case(case))
    entry, t_entry = _load_entry(case)
    arrivals = {}
    for name, h in hist.items():
        r = float(np.linalg.norm(h["coords"] - entry))
        t_det = wave_arrival(h["t"], h["acceleration"], t_entry, a["wave_threshold"])
        arrivals[name] = {"distance": r, "t_entry": t_entry, "detected": t_det,
                          "after_entry": t_det - t_entry,
                          "p_analytic": r / c_p, "s_analytic": r / c_s,
                          "apparent_speed": r / (t_det - t_entry) if t_det > t_entry else None}
    # the bare soil under a surface load (track.count = 0), or a site without a building,
    # is no thesis model: no thesis comparison, no thesis table
    has_track = bool(case["track.count"])
    thesis_site = has_track and bool(case["building.present"])
    ours = _thesis_comparison(hist, out_dir / FIELDS_H5) if thesis_site else {}
    comparison = {k: {"thesis": v, "railvib": ours.get(k)} for k, v in THESIS.items()
                  if thesis_site and not k.endswith("arrival_basement_wall")}
    # arrivals on the thesis's clock (t = 0 with the wheel at x = 0) at the wall's far end
    arrival = thesis_clock_arrival(case, hist) if thesis_site else None
    if arrival is not None:
        for key, c in (("p_wave_arrival_basement_wall", c_p),
                       ("s_wave_arrival_basement_wall", c_s)):
            comparison[key] = {"thesis": THESIS[key],
                               "railvib": arrival["detected"] if key[0] == "p" else None,
                               "analytic": arrival["t_entry"] + arrival["distance"] / c}
    rows = (thesis_rows(case, out_dir, hist, ours, arrival, modal=solver == "modal")
            if thesis_site else [])
    origin = ("the first wheel enters the flexible rail" if has_track
              else "the surface load enters the soil")
    x, force = _contact(out_dir, solver)
    if x is not None and not np.size(x, 1):       # no wheel (the surface load): no figure
        x = force = None
    extra = []
    pm = peak_map(out_dir / FIELDS_H5, case["geometry.z1"], out_dir / "figures" / "peak_map.png")
    if pm is not None:
        extra.append({"id": "peak_map", "file": "figures/peak_map.png",
                      "title": "Peak velocity map: ground surface and slab tops", "data": pm})
    floors = floor_summary(results, {name: h["role"] for name, h in hist.items()})
    text = [("Model and settings", model_summary(case, out_dir, solver)),
            ("Assessment per floor", format_floor_table(floors)),
            *([("Comparison with the thesis", format_thesis_table(rows))] if rows else []),
            ("Wave arrivals", format_comparison(comparison, arrivals, c_p, c_s, origin))]
    free = free_field_summary(hist, line_probes(case))            # [[probes.line]]
    if free:
        text.insert(2, ("Free field (probe lines)", format_free_field(free)))
    files = write_report(out_dir, results, hist, None if x is None else (x, force),
                         extra_figures=extra, extra_text=text,
                         extra_data={"free_field": free} if free else None)
    summary = {"solver": solver, "results": results, "wave_speeds": {"c_P": c_p, "c_S": c_s},
               "wave_arrivals": arrivals, "thesis_comparison": comparison,
               "thesis_table": rows,
               "verdict": {k: v["passed"] for k, v in results.items()},
               "floors": floors, "free_field": free,
               "report": {k: str(p) for k, p in files.items()}}
    write_json(out_dir / ASSESSMENT_JSON, json.loads(json.dumps(summary, default=float)),
               ctx.provenance(ASSESSMENT_JSON, upstream))
    rep.info(format_table(results))
    rep.info(format_floor_table(floors))
    if free:
        rep.info(format_free_field(free))
    if rows:
        rep.info(format_thesis_table(rows))
    rep.info(format_comparison(comparison, arrivals, c_p, c_s, origin))
    rep.info(f"assessed the results of the {SOLVER_TEXT[solver]}")
    rep.info(f"wrote {out_dir / ASSESSMENT_JSON}, {files.get('html')}, {files.get('markdown')}")
    return summary


def format_comparison(comparison: dict, arrivals: dict, c_p: float, c_s: float,
                      origin: str = "the first wheel enters the flexible rail") -> str:
    """Printable thesis comparison (none when ``comparison`` is empty) and wave-arrival
    table, the arrivals counted from ``origin``."""
    lines = ["thesis values (benchmarks.md section 2; arrivals on the thesis's clock, t = 0 "
             "with the wheel at x = 0, at basement_wall_far):",
             f"  {'quantity':42s} {'thesis':>12s} {'railvib':>12s}"] if comparison else []
    for k, v in comparison.items():
        ours = v.get("railvib")
        lines.append(f"  {k:42s} {v['thesis']:12.4g} "
                     + (f"{ours:12.4g}" if ours is not None else f"{'-':>12s}")
                     + (f"   (analytic {v['analytic']:.3f} s)" if "analytic" in v else ""))
    lines.append(f"wave arrivals (subgrade c_P = {c_p:.1f} m/s, c_S = {c_s:.1f} m/s; time after "
                 f"{origin}):")
    lines.append(f"  {'probe':16s} {'r [m]':>7s} {'detected [s]':>13s} {'r/c_P [s]':>10s} "
                 f"{'r/c_S [s]':>10s}")
    for name, w in arrivals.items():
        lines.append(f"  {name:16s} {w['distance']:7.2f} {w['after_entry']:13.4f} "
                     f"{w['p_analytic']:10.4f} {w['s_analytic']:10.4f}")
    return "\n".join(lines)


#: How the report names the solver that produced the numbers.
SOLVER_TEXT = {"modal": "modal solution (railvib modal + mbs + reconstruct)",
               "transient": "full-order time integration (railvib transient)"}


def model_summary(case: Case, out_dir: Path, solver: str = "modal") -> str:
    """What an assessment rests on, for the report: the solver, model size, element and
    damping formulation, modes and band (or the time integration), MBS settings, versions
    and input hashes (rank 0)."""
    import h5py

    lines = [f"case                 {case['case.name']} (preset {case['case.preset']})",
             f"mesh                 refinement {case['mesh.refinement']}, hexahedra: "
             f"{case['modal.hex_formulation']}"]
    if solver == "transient":
        lines.extend(_site_summary(case))
        lines.extend(_transient_summary(case, out_dir / TRANSIENT_H5))
        return "\n".join(lines)
    lines.append(f"solver               {SOLVER_TEXT['modal']}")
    lines.extend(_site_summary(case))
    modes_path, mbs_path = out_dir / MODES_H5, out_dir / MBS_H5
    if modes_path.exists():
        with h5py.File(modes_path, "r") as f:
            freq = f["modes/frequency_hz"][()]
            n_nodes = f["mesh/points"].shape[0]
            stats = json.loads(f.attrs.get("stats", "{}"))
            lines.append(f"model                {n_nodes:,} nodes, {stats.get('n_dofs', 0):,} free "
                         f"DOFs, solved on {stats.get('ranks', '?')} rank(s)"
                         + (", MUMPS out of core" if stats.get("out_of_core") else ""))
            lines.append(f"modes                {len(freq)} computed, {freq[0]:.3f} - "
                         f"{freq[-1]:.3f} Hz")
            lines.append(f"software             railvib {f.attrs.get('railvib_version', '?')}, "
                         f"PETSc {f.attrs.get('petsc_version', '?')}, SLEPc "
                         f"{f.attrs.get('slepc_version', '?')}")
            lines.append(f"modes.h5 inputs      sha256 {f.attrs.get('inputs_sha256', '?')}")
    if case["modal.damping"] == "uniform":
        damping = f"uniform {100 * case['modal.damping_ratio']:g} %"
    else:
        ratios = ", ".join(f"{k} {100 * v['damping_ratio']:g} %"
                           for k, v in case["materials"].items() if k != "rigid_rail")
        damping = (f"per material (strain energy): {ratios}; pads "
                   f"{100 * case['modal.damping_ratio']:g} %")
    lines.append(f"damping              {damping}")
    if mbs_path.exists():
        mbs = MbsFile(mbs_path).summary()
        m, zeta, dt = mbs["n_modes"], mbs["zeta"], mbs["dt"]
        lines.append(f"modal damping used   {100 * zeta.min():.2f} - {100 * zeta.max():.2f} "
                     f"% over {m} modes")
        lines.append(f"mbs.h5 inputs        sha256 {mbs['inputs_sha256']}")
        lines.append(f"multibody            {case['vehicle.type']} at {case['vehicle.speed']:g} "
                     f"m/s, {m} modes, static correction "
                     f"{'on' if case['mbs.static_correction'] else 'off'}, dt {dt:.2e} s, "
                     f"irregularity {case['irregularity.type']}")
    return "\n".join(lines)


def _site_summary(case: Case) -> list[str]:
    """The building and the tracks in one line each."""
    from ..mbs.case_vehicle import tracks_line
    from ..mesh.building import building_line
    from ..mesh.interfaces import site_line

    out = [f"building             {building_line(case)}"]
    out.append("track bed            " + site_line(case))
    tracks = tracks_line(case)
    if tracks:
        out.append(f"tracks               {tracks} (wave arrivals: train 1)")
    return out


def _engine_text(stats: dict) -> str:
    """The assessment's words on the run's engine (its declaration's ``report``,
    :data:`railvib_hpc.time_engines.ENGINES`; the direct engine's for results recorded
    before there were others)."""
    from ..time_engines import ENGINES, declaration

    name = stats.get("engine")
    spec = declaration(name if name in ENGINES else None)
    return spec.report.format(rho_inf=stats.get("rho_inf", "?"))


def _transient_summary(case: Case, path: Path) -> list[str]:
    """Report lines of a full-order (``railvib transient``) solution."""
    stats, key = TransientFile(path).summary()
    faces = ", ".join(f"{k} {case[f'boundary.{k}']}" for k in
                      ("x_min", "x_max", "y_min", "y_max", "base"))
    d = case["damping"]
    damping = {"rayleigh": f"Rayleigh {100 * case['modal.damping_ratio']:g} % at "
                           f"{d['f1']:g} and {d['f2']:g} Hz",
               "per_material": f"per-material Rayleigh at {d['f1']:g} and {d['f2']:g} Hz",
               "none": "none"}[d["model"]]
    return [f"model                {stats.get('n_nodes', 0):,} nodes, "
            f"{stats.get('n_dofs', 0):,} free DOFs, solved on {stats.get('ranks', '?')} rank(s)",
            f"solver               {SOLVER_TEXT['transient']}, "
            + _engine_text(stats)
            +
            f"dt {stats.get('dt', 0):.3e} s, {stats.get('n_steps', '?')} steps",
            f"boundaries           {faces}"
            + (f", virtual thickness {case['boundary.virtual_thickness']:g} m"
               if case["boundary.virtual_thickness"] > 0 else ""),
            f"damping              {damping}" + (", rail-pad dashpots" if d["pads"] else ""),
            f"multibody            {case['vehicle.type']} at {case['vehicle.speed']:g} m/s, "
            f"irregularity {case['irregularity.type']}",
            f"transient.h5 inputs  sha256 {key}"]


def compute(ctx: StageContext) -> AssessmentOutput:
    """``railvib assess`` (collective): rank 0 verifies the inputs and assesses
    (:func:`assess_case`), every rank gets the output."""
    with ctx.rep.stage("assess"):
        return on_root(lambda: AssessmentOutput.of_summary(assess_case(ctx), ctx.out_dir),
                       ctx.comm)


#: ``assessment.json`` (with the report): the whole case; computed from the modal
#: solution's files (a transient folder's are its own stage's rows).
ASSESSMENT_FILE = StageFile(ASSESSMENT_JSON, "assess", 2, ALL_KEYS,
                            (MODES_H5, STATIC_H5, MBS_H5, FIELDS_H5, PROBES_H5),
                            (REPORT_MD, REPORT_HTML, REPORT_JSON),
                            ("mesh.file", "irregularity.file"))

STAGE = Stage(name="assess", help="evaluate the building response against vibration "
              "standards", products=(ASSESSMENT_FILE,),
              reads=(MODES_H5, STATIC_H5, MBS_H5, FIELDS_H5, PROBES_H5,
                     *TRANSIENT_INPUTS), compute=compute,
              needs=("modal", "mbs", "reconstruct", "transient"))


def run_assess_stage(case: Case, out_dir: Path, comm: MPI.Comm, rep: Reporter,
                     petsc_options: list[str] | None = None) -> dict:
    """The ``assess`` stage from a script: :data:`STAGE` through the runner (the folder's
    lock; no ``run.json`` entry). Returns its summary (every rank)."""
    runner = StageRunner(out_dir, comm, rep, petsc_options or (), command="assess")
    return dict(runner.run(STAGE, case, record=False).result.summary)
