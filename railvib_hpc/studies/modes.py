"""Modal truncation: the response against the number of modes, with and without the static
correction.

One modal solve with the largest mode count (and ``static.h5`` when a corrected run is
asked for) in ``<out>/modes/model``; each variant ``n<m>_modal`` / ``n<m>_corrected`` links
to it and runs only the MBS with ``mbs.n_modes = m`` and ``mbs.static_correction`` off/on,
then the probe histories (with the static-correction basis in the displacements when it is
on).

Reference: the most modes, corrected if corrected runs were asked for. For each variant the
deviation of every quantity (building peak accelerations, peak contact force, max rail
deflection) from the reference; "modes needed for tolerance %": the smallest mode count
from which on (for it and every larger count) all quantities stay within the tolerance,
separately without and with the correction, and the same per quantity (building
accelerations, contact force and rail deflection usually need very different counts).
The reference itself is truncated: the change
between the two largest corrected counts is reported as its own convergence indicator.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..config import Case
from .common import StudyPlan, Variant, relative, response_quantities
from .protocol import Study
from .report import figure, fmt, pct, save, transpose

TITLE = "Modal truncation study"


def _tag(corrected: bool) -> str:
    return "corrected" if corrected else "modal"


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """A shared model with the most modes; one MBS variant per (count, correction)."""
    n_max = max(settings["n_modes"])
    corr = settings["static_correction"]
    model = (f"modal.n_modes={n_max}", "modal.f_max=0.0",
             f"mbs.static_correction={'true' if True in corr else 'false'}")
    variants = []
    for n in settings["n_modes"]:
        for c in corr:
            variants.append(Variant(
                name=f"n{n}_{_tag(c)}",
                overrides=(*model[:2], f"mbs.n_modes={n}",
                           f"mbs.static_correction={'true' if c else 'false'}"),
                parameter={"n_modes": n, "static_correction": c}, shared=True))
    return StudyPlan("modes", tuple(variants), shared_overrides=model)


def _quantities(res: dict, settings: dict) -> dict[str, float]:
    q = response_quantities(res, settings["probes"])
    q["max rail deflection"] = res["mbs"]["max_rail_deflection"]
    return q


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """Deviation from the reference per variant and the modes needed for the tolerance."""
    done = [v for v in plan_.variants if v.name in results]
    if not done:
        return {"title": TITLE, "verdict": {"text": "no variant finished", "ok": None},
                "tables": [], "rows": []}
    tol = settings["tolerance"] / 100.0
    corrected_runs = [v for v in done if v.parameter["static_correction"]]
    pool = corrected_runs or done
    ref = max(pool, key=lambda v: v.parameter["n_modes"])
    qref = _quantities(results[ref.name], settings)
    names = list(qref)
    data = []
    for v in done:
        r = results[v.name]
        q = _quantities(r, settings)
        dev = {k: relative(q[k], qref[k]) for k in names}
        worst = max((k for k in names if dev[k] is not None), key=lambda k: dev[k],
                    default=None)
        data.append({"variant": v.name, "n_modes": v.parameter["n_modes"],
                     "static_correction": v.parameter["static_correction"],
                     "band_hz": r["model"]["f_max_hz"], "quantities": q, "deviation": dev,
                     "max_deviation": dev[worst] if worst else None, "governing": worst,
                     "wall_s": r["timings"]["total"]})
    head = ["variant", "modes", "static corr.", "band [Hz]", *names, "max deviation"]
    rows = [[d["variant"], fmt(d["n_modes"]), fmt(d["static_correction"]), fmt(d["band_hz"]),
             *(fmt(d["quantities"][k]) for k in names), pct(d["max_deviation"])]
            for d in data]
    drows = [[d["variant"], *(pct(d["deviation"][k]) for k in names)] for d in data]
    needed, per_quantity = {}, {}
    for c in sorted({d["static_correction"] for d in data}):
        seq = sorted((d for d in data if d["static_correction"] == c),
                     key=lambda d: d["n_modes"])
        needed[_tag(c)] = _first_within(seq, lambda e: e["max_deviation"], tol)
        per_quantity[_tag(c)] = {k: _first_within(seq, lambda e, k=k: e["deviation"][k], tol)
                                 for k in names}
    indicator = None
    cr = sorted((d for d in data if d["static_correction"] == ref.parameter[
        "static_correction"]), key=lambda d: d["n_modes"])
    if len(cr) >= 2:
        indicator = {"from": cr[-2]["variant"], "to": cr[-1]["variant"],
                     "max_change": cr[-2]["max_deviation"], "quantity": cr[-2]["governing"]}
    verdict = _verdict(needed, ref, settings, indicator, data, per_quantity)
    tables = [
        {"title": "Responses", **dict(zip(("head", "rows"), transpose(head, rows))),
         "note": "Accelerations in m/s² (a_z vertical, |a| total peak), contact force in N, "
                 "rail deflection in m; band: frequency of the highest mode used."},
        {"title": f"Deviation from the reference {ref.name}",
         **dict(zip(("head", "rows"), transpose(["variant", *names], drows)))},
        {"title": "Modes needed", "head": ["static correction",
                                            f"modes for {settings['tolerance']:g} %"],
         "rows": [[k, fmt(v) if v is not None else "not reached"]
                  for k, v in needed.items()]},
        {"title": f"Modes needed per quantity (within {settings['tolerance']:g} % of "
                  f"{ref.name} from this count on)",
         "head": ["quantity", *(f"{tag}" for tag in per_quantity)],
         "rows": [[k, *(fmt(per_quantity[tag][k]) if per_quantity[tag][k] is not None
                        else "not reached" for tag in per_quantity)] for k in names]},
    ]
    return {"title": TITLE, "verdict": verdict, "tables": tables, "rows": data,
            "reference": ref.name, "modes_needed": needed,
            "modes_needed_per_quantity": per_quantity, "reference_change": indicator}


def _first_within(seq: list[dict], deviation, tol: float) -> int | None:
    """Smallest mode count of ``seq`` (sorted by count) from which on every deviation
    stays within ``tol``; None when even the largest count does not."""
    for i, d in enumerate(seq):
        if all(deviation(e) is not None and deviation(e) <= tol for e in seq[i:]):
            return d["n_modes"]
    return None


def _group_summary(per_quantity: dict[str, int | None]) -> str:
    """'building accelerations 600, contact force 1000, rail deflection 50' (the largest
    count needed within each group; 'not reached' when any member is not reached)."""
    groups = {"building accelerations": [k for k in per_quantity
                                         if k not in ("peak contact force",
                                                      "max rail deflection")],
              "contact force": ["peak contact force"], "rail deflection": ["max rail deflection"]}
    parts = []
    for label, keys in groups.items():
        vals = [per_quantity[k] for k in keys if k in per_quantity]
        if not vals:
            continue
        parts.append(f"{label} {'not reached' if None in vals else max(vals)}")
    return ", ".join(parts)


def _verdict(needed: dict, ref: Variant, settings: dict, indicator: dict | None,
             data: list, per_quantity: dict | None = None) -> dict:
    tol = settings["tolerance"]
    parts = []
    n_ref = ref.parameter["n_modes"]
    ref_tag = _tag(ref.parameter["static_correction"])
    for tag, n in needed.items():
        label = "with the static correction" if tag == "corrected" else "modes only"
        if n is None:
            parts.append(f"{label}: not reached with {max(d['n_modes'] for d in data)} modes")
        elif n == n_ref and tag == ref_tag:
            parts.append(f"{label}: only the reference itself ({n} modes; no smaller count "
                         "is within the tolerance)")
        else:
            parts.append(f"{label}: {n} modes")
    text = (f"modes needed to stay within {tol:g} % of the reference ({ref.name}): "
            + "; ".join(parts))
    if per_quantity:
        text += ". Per quantity: " + "; ".join(
            f"{'with the static correction' if tag == 'corrected' else 'modes only'}: "
            f"{_group_summary(pq)}" for tag, pq in per_quantity.items())
    if indicator and indicator["max_change"] is not None:
        text += (f". Reference check: {indicator['from']} differs from it by "
                 f"{100 * indicator['max_change']:.2f} % ({indicator['quantity']})")
        if indicator["max_change"] > tol / 100.0:
            text += (" — the reference itself is not converged: the counts above are lower "
                     "bounds; add more modes")
    ok = needed.get("corrected", needed.get("modal")) is not None
    return {"text": text, "ok": ok, "modes_needed": needed, "tolerance_percent": tol,
            "reference": ref.name}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """Building peaks, contact force and rail deflection against the number of modes."""
    data = analysis.get("rows") or []
    if not data:
        return []
    probes = settings["probes"]
    fig = figure(figsize=(12, 7))
    axes = fig.subplots(2, 3).ravel()
    panels = [(f"{p} |a|", f"{p}: peak total acceleration [m/s²]") for p in probes[:4]]
    panels += [("peak contact force", "peak contact force [N]"),
               ("max rail deflection", "max rail deflection [m]")]
    for ax, (key, label) in zip(axes, panels):
        for c, style in ((False, "o--"), (True, "s-")):
            seq = sorted((d for d in data if d["static_correction"] == c),
                         key=lambda d: d["n_modes"])
            if seq:
                ax.plot([d["n_modes"] for d in seq], [d["quantities"][key] for d in seq],
                        style, ms=4, label="with static correction" if c else "modes only")
        ax.set_xlabel("modes")
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    for ax in axes[len(panels):]:
        ax.set_visible(False)
    return [save(fig, fig_dir / "modes.png")]


STUDY = Study(
    name="modes",
    help=("modal truncation: the response against the number of modes, with and without "
          "the static correction"),
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    sorted_settings=("n_modes", "static_correction"),
    needs_track="it compares numbers of the track's modes under the vehicle (the modal path)",
)
