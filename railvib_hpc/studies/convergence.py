"""Mesh convergence: the pipeline (mesh, modes, MBS, probes) at several refinements.

Variants ``r<level>`` set ``mesh.refinement``; each has its own mesh and modes. Per level:
nodes, DOFs, hexahedra, the lowest natural frequencies, the peak contact force and the peak
building accelerations (vertical and total) at the study's probes. Between levels: the
relative changes; on the finest level: a Richardson estimate per quantity
(:mod:`.richardson`, mesh size ``h = DOFs^(-1/3)``; observed order from the three finest
levels when available, else the formal order 2).

Verdict: "converged within X %", X the largest estimated error of the finest level over
the compared quantities; it passes when X <= ``tolerance``. ``solver = direct`` runs every
level with the full-order time integration (``railvib transient``): the responses are
compared, no natural frequencies. The number of modes is the
case's at every level, so each level's band ends at its own highest frequency (listed).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..config import Case
from .common import CONTACT_FORCE, StudyPlan, Variant, relative, response_quantities
from .protocol import Study
from .report import figure, fmt, pct, save
from .richardson import extrapolate, mesh_sizes

TITLE = "Mesh convergence study"


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """One variant per refinement level."""
    variants = tuple(Variant(name=f"r{lv:g}", overrides=(f"mesh.refinement={lv!r}",),
                             parameter={"refinement": lv})
                     for lv in settings["levels"])
    return StudyPlan("convergence", variants)


def _quantities(res: dict, settings: dict) -> dict[str, float]:
    out = {f"f{i + 1} [Hz]": f for i, f in       # none with solver = direct
           enumerate(res["model"]["frequencies_hz"][:settings["n_frequencies"]])
           if f is not None}
    out.update(response_quantities(res, settings["probes"]))
    return out


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """Tables, Richardson estimates and the verdict from the finished levels."""
    levels = [v for v in plan_.variants if v.name in results]
    levels.sort(key=lambda v: results[v.name]["model"]["n_dofs"])
    notes = []
    uniq: list[Variant] = []
    for v in levels:                               # equal meshes (rounding) count once
        if uniq and results[uniq[-1].name]["model"]["n_dofs"] == \
                results[v.name]["model"]["n_dofs"]:
            notes.append(f"level {v.name} gives the same mesh as {uniq[-1].name}: ignored")
            continue
        uniq.append(v)
    rows, data = [], []
    for v in uniq:
        r = results[v.name]
        q = _quantities(r, settings)
        data.append({"variant": v.name, "refinement": v.parameter["refinement"],
                     "n_nodes": r["model"]["n_nodes"], "n_dofs": r["model"]["n_dofs"],
                     "n_hexes": r["model"]["n_hexes"], "band_hz": r["model"]["f_max_hz"],
                     "wall_s": r["timings"]["total"], "quantities": q})
    names = list(data[0]["quantities"]) if data else []
    levels_table = {
        "title": "Levels",
        "head": ["level", "refinement", "nodes", "DOFs", "hexahedra", "band [Hz]", "wall [s]"],
        "rows": [[d["variant"], fmt(d["refinement"]), fmt(d["n_nodes"]), fmt(d["n_dofs"]),
                  fmt(d["n_hexes"]), fmt(d["band_hz"]), fmt(d["wall_s"], 3)] for d in data]}
    rich: dict[str, dict] = {}
    if len(data) >= 2:
        h = mesh_sizes([d["n_dofs"] for d in data])
        for k in names:
            rich[k] = extrapolate([d["quantities"][k] for d in data], h,
                                  settings["formal_order"]).as_dict()
    head = ["quantity", *(d["variant"] for d in data),
            *(f"{a['variant']}→{b['variant']}" for a, b in zip(data, data[1:])),
            "extrapolated", "order", "basis", "est. error"]
    rows = []
    for k in names:
        vals = [d["quantities"][k] for d in data]
        e = rich.get(k)
        rows.append([k, *(fmt(v) for v in vals),
                     *(pct(relative(a, b)) for a, b in zip(vals, vals[1:])),
                     fmt(e["extrapolated"]) if e else "–",
                     fmt(e["observed_order"], 3) if e else "–",
                     (e["basis"] + (", oscillating" if e["oscillatory"] else "")) if e else "–",
                     pct(e["error"]) if e else "–"])
    quantities_table = {
        "title": "Quantities per level, relative changes and Richardson estimate",
        "head": head, "rows": rows,
        "note": ("Frequencies in Hz, accelerations (a_z vertical, |a| total peak) in m/s², "
                 + ("contact force in N. " if CONTACT_FORCE in names else
                    "no contact force (no vehicle: a case without a track). ")
                 + "Mesh size h = DOFs^(-1/3); observed order from the "
                 "three finest levels (Celik et al. 2008, any refinement ratios). basis "
                 "'observed': monotone, order in [0.5, 8], error = |finest - extrapolated| / "
                 f"|extrapolated|; 'assumed': two levels, formal order "
                 f"{settings['formal_order']:g}; 'unreliable': oscillating or order outside "
                 "[0.5, 8], the error is then the largest of the assumed-order estimate and "
                 "the last two changes.")}
    tables = [levels_table, quantities_table]
    sections = []
    verdict = _verdict(rich, data, settings, notes)
    if notes:
        sections.append(("Notes", "\n".join(f"* {n}" for n in notes)))
    return {"title": TITLE, "verdict": verdict, "tables": tables, "sections": sections,
            "levels": data, "richardson": rich, "notes": notes}


def _verdict(rich: dict, data: list, settings: dict, notes: list) -> dict:
    tol = settings["tolerance"] / 100.0
    if len(data) < 2:
        return {"text": f"not enough levels finished ({len(data)}; need 2)", "ok": None,
                "error": None}
    worst = max(rich, key=lambda k: rich[k]["error"])
    err = rich[worst]["error"]
    ok = bool(err <= tol)
    bases = {e["basis"] for e in rich.values()}
    fine = data[-1]
    where = f"at refinement {fine['refinement']:g} ({fine['n_dofs']:,} DOFs)"
    if ok:
        text = (f"converged within {100 * err:.2f} % {where}: meets the "
                f"{settings['tolerance']:g} % target")
    else:
        text = (f"NOT converged within the {settings['tolerance']:g} % target {where}: "
                f"estimated error up to {100 * err:.2f} %")
    text += (f" (largest: {worst}; {len(data)} levels, estimates "
             f"{'/'.join(sorted(bases))})")
    within = sorted(k for k, e in rich.items() if e["error"] <= tol)
    if not ok and within:
        text += f"; within the target: {', '.join(within)}"
    return {"text": text, "ok": ok, "error": err, "governing": worst,
            "tolerance_percent": settings["tolerance"], "finest": fine["variant"]}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """Quantities relative to the finest level against DOFs (stars: Richardson limits where
    the observed order is reliable)."""
    data = analysis["levels"]
    if len(data) < 2:
        return []
    dofs = np.array([d["n_dofs"] for d in data], dtype=float)
    names = list(data[0]["quantities"])
    fig = figure(figsize=(11, 4.5))
    ax1, ax2 = fig.subplots(1, 2)
    for k in names:
        vals = np.array([d["quantities"][k] for d in data], dtype=float)
        target = ax1 if "Hz" in k else ax2
        line = target.plot(dofs, vals / vals[-1], "o-", lw=1, ms=4, label=k)[0]
        ext = analysis["richardson"].get(k, {})
        if ext.get("basis") == "observed" and ext.get("extrapolated"):
            target.plot([dofs[-1] * 1.35], [ext["extrapolated"] / vals[-1]], "*", ms=8,
                        color=line.get_color())
    force = ", contact force" if CONTACT_FORCE in names else ""
    for ax, title in ((ax1, "lowest natural frequencies"),
                      (ax2, f"peak responses (building probes{force})")):
        ax.set_xscale("log")
        ax.axhline(1.0, color="k", lw=0.6)
        tol = settings["tolerance"] / 100.0
        ax.axhspan(1 - tol, 1 + tol, color="0.9", zorder=0)
        ax.set_xlabel("free DOFs")
        ax.set_ylabel("value / value of the finest level (*: Richardson limit)")
        ax.set_title(title)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7, ncol=2)
    return [save(fig, fig_dir / "convergence.png")]


STUDY = Study(
    name="convergence",
    help=("mesh convergence: the response at several refinements, Richardson "
          "extrapolation"),
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    sorted_settings=("levels",),
)
