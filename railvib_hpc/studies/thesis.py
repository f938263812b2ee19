"""Thesis comparison: the baseline with the thesis's mode count and with its band, each
with the thesis's unspecified start as a sensitivity band (wheelset drop heights).

The thesis extracted 300 modes and reports their range as 9.56-57.87 Hz (§3); for this
model 300 modes end far lower (Weyl's law: the domain has about 2.5 times as many modes
below 57.87 Hz). Both readings are run: one shared modal solve with every mode below
``band_hz`` (``modal.f_max``, ``<out>/thesis/model``), then for every drop height (and
contact damping) one MBS run with the first ``n_modes`` modes (``n300_*``) and one with all
of them (``band_*``), and the probe histories.

The thesis's wheelset is "dropped from a small distance" (§2.2) whose height it does not
give, nor the contact damping. The drop heights (default 0, 0.01 and 0.1 mm; 24-48 kN
impact peaks on a rigid rail against 7.7 kN static) are a sensitivity band on that
unspecified start: they are not fitted to the thesis's results.

Compared with the thesis: the peak vertical accelerations of slabs 1 and 2 (0.060 and
0.045 m/s²), the total accelerations of floors 1 and 2 (0.041, 0.052 m/s²) and the onset
at the far end of the track-side basement wall on the thesis's clock (P wave 0.16 s,
t = 0 with the wheel at x = 0). Verdict: which variants bracket the thesis's slab values.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..assess.thesis import THESIS
from ..config import Case
from .common import StudyPlan, Variant
from .protocol import Study
from .report import figure, fmt, save, transpose

TITLE = "Thesis comparison: mode count vs band, and the drop of the wheelset"

#: (result key, probe, thesis key, label)
_COMPARED = (
    ("acc_vertical", "slab1", "slab1_vertical_acceleration", "slab 1 a_z"),
    ("acc_vertical", "slab2", "slab2_vertical_acceleration", "slab 2 a_z"),
    ("acc_total", "slab1", "floor1_total_acceleration", "floor 1 |a|"),
    ("acc_total", "slab2", "floor2_total_acceleration", "floor 2 |a|"),
)
ARRIVAL_PROBE = "basement_wall_far"


def _name(label: str, drop: float, damping: float, many_c: bool) -> str:
    name = f"{label}_drop{drop * 1e3:g}mm"
    return name + (f"_c{damping:g}" if many_c else "")


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """A shared model with every mode below the band; (count, band) x drops x dampings."""
    band = settings["band_hz"]
    model = (f"modal.f_max={band!r}",)
    many_c = len(settings["contact_damping"]) > 1
    clock = {"x_start": case["vehicle.x_start"], "speed": case["vehicle.speed"],
             "x1": case["geometry.x1"]}
    variants = []
    for label, n in (("n" + str(settings["n_modes"]), settings["n_modes"]), ("band", 0)):
        for d in settings["drop_heights"]:
            for c in settings["contact_damping"]:
                variants.append(Variant(
                    name=_name(label, d, c, many_c),
                    overrides=(*model, f"mbs.n_modes={n}", f"vehicle.drop_height={d!r}",
                               f"vehicle.contact_damping={c!r}"),
                    parameter={"modes": "band" if n == 0 else "count", "n_modes": n,
                               "band_hz": band, "drop_height": d, "contact_damping": c,
                               **clock},
                    shared=True))
    return StudyPlan("thesis", tuple(variants), shared_overrides=model)


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """The thesis-vs-project table of every variant and the verdict."""
    done = [v for v in plan_.variants if v.name in results]
    if not done:
        return {"title": TITLE, "verdict": {"text": "no variant finished", "ok": None},
                "tables": [], "rows": []}
    data = []
    for v in done:
        r, p = results[v.name], v.parameter
        probes = r["probes"]
        values = {label: probes[probe][key] if probe in probes else None
                  for key, probe, _, label in _COMPARED}
        onset = probes.get(ARRIVAL_PROBE, {}).get("t_onset")
        data.append({
            "variant": v.name, "modes": p["modes"], "drop_height": p["drop_height"],
            "contact_damping": p["contact_damping"],
            "modes_used": r["model"]["modes_used"], "f1_hz": r["model"]["frequencies_hz"][0],
            "f_top_hz": r["model"]["f_max_hz"],
            "peak_contact_force": r["mbs"]["peak_contact_force"],
            "min_contact_force": r["mbs"]["min_contact_force"],
            "loss_of_contact_steps": r["mbs"]["loss_of_contact_steps"],
            "values": values,
            "onset_thesis_clock": (None if onset is None
                                   else onset + p["x_start"] / p["speed"]),
            "t_entry": p["x1"] / p["speed"], "wall_s": r["timings"]["total"]})
    labels = [c[3] for c in _COMPARED]
    head = ["variant", "modes used", "highest mode [Hz]", "f1 [Hz]", "drop [mm]",
            "contact damping [N s/m²]", "peak contact force [kN]", "min contact force [kN]",
            *(f"{x} [m/s²]" for x in labels), f"{ARRIVAL_PROBE} onset, thesis clock [s]"]
    thesis_row = ["thesis", "300", "57.87", "9.56", "unspecified", "unspecified",
                  "(figure only)", "–", *(fmt(THESIS[c[2]]) for c in _COMPARED),
                  fmt(THESIS["p_wave_arrival_basement_wall"])]
    rows = [thesis_row] + [[
        d["variant"], fmt(d["modes_used"]), fmt(d["f_top_hz"]), fmt(d["f1_hz"]),
        fmt(1e3 * d["drop_height"]), fmt(d["contact_damping"]),
        fmt(d["peak_contact_force"] / 1e3), fmt(d["min_contact_force"] / 1e3),
        *(fmt(d["values"][x]) for x in labels), fmt(d["onset_thesis_clock"], 3)]
        for d in data]
    ratio_rows = [[d["variant"], *(fmt(THESIS[c[2]] / d["values"][c[3]], 3)
                                   if d["values"][c[3]] else "–" for c in _COMPARED)]
                  for d in data]
    verdict = _verdict(data, settings)
    tables = [
        {"title": "Thesis vs this project",
         **dict(zip(("head", "rows"), transpose(head, rows))),
         "note": "Peak accelerations over the run. The drop heights are the thesis's "
                 "unspecified start (§2.2: 'dropped from a small distance'), a sensitivity "
                 "band, not a fit. Onset: first time |a| reaches "
                 "assessment.wave_threshold of its peak, on the thesis's clock (t = 0 with "
                 "the wheel at x = 0; the flexible rail is entered at "
                 f"{data[0]['t_entry']:.3f} s); a truncated modal basis is not causal."},
        {"title": "Thesis value / this project",
         **dict(zip(("head", "rows"), transpose(["variant", *labels], ratio_rows)))},
    ]
    return {"title": TITLE, "verdict": verdict, "tables": tables, "rows": data}


def _verdict(data: list[dict], settings: dict[str, Any]) -> dict:
    """Which of the thesis's building accelerations each mode set's drop band brackets."""
    parts, bracket = [], {}
    for modes in ("count", "band"):
        sel = [d for d in data if d["modes"] == modes]
        if not sel:
            continue
        what = (f"the first {settings['n_modes']} modes (to {sel[0]['f_top_hz']:.2f} Hz)"
                if modes == "count" else
                f"the {settings['band_hz']:g} Hz band ({sel[0]['modes_used']} modes)")
        inside, ranges = [], []
        for _, _, tkey, label in _COMPARED:
            vals = [d["values"][label] for d in sel if d["values"][label] is not None]
            if not vals:
                continue
            lo, hi = min(vals), max(vals)
            ranges.append(f"{label} {lo:.3g}-{hi:.3g} (thesis {THESIS[tkey]:g})")
            if lo <= THESIS[tkey] <= hi:
                inside.append(label)
        bracket[modes] = inside
        drops = sorted({d["drop_height"] * 1e3 for d in sel})
        parts.append(f"{what}, drops {', '.join(f'{h:g}' for h in drops)} mm: "
                     + "; ".join(ranges) + f" m/s² -> brackets {len(inside)} of "
                     f"{len(ranges)} thesis values" + (f" ({', '.join(inside)})"
                                                       if inside else ""))
    text = (". ".join(p[:1].upper() + p[1:] for p in parts)
            + ". The drop height is the thesis's unspecified start, a sensitivity band, not a "
            "fitted value.")
    return {"text": text, "ok": None, "brackets_thesis": bracket}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """Slab accelerations per variant with the thesis's values, and the contact forces."""
    data = analysis.get("rows") or []
    if not data:
        return []
    import numpy as np

    fig = figure(figsize=(12, 4.5))
    a1, a2 = fig.subplots(1, 2, width_ratios=(2, 1))
    x = np.arange(len(data))
    width = 0.8 / len(_COMPARED)
    for i, (_, _, tkey, label) in enumerate(_COMPARED):
        vals = [d["values"][label] or 0.0 for d in data]
        bars = a1.bar(x + i * width, vals, width, label=label)
        a1.axhline(THESIS[tkey], color=bars.patches[0].get_facecolor(), ls="--", lw=0.8)
    a1.set_yscale("log")
    a1.set_xticks(x + 0.4 - width / 2, [d["variant"] for d in data], rotation=30,
                  ha="right", fontsize=7)
    a1.set_ylabel("peak acceleration [m/s²] (dashed: thesis)")
    a1.legend(fontsize=7)
    a1.grid(alpha=0.3, axis="y")
    a2.bar(x, [d["peak_contact_force"] / 1e3 for d in data], 0.6)
    a2.set_xticks(x, [d["variant"] for d in data], rotation=30, ha="right", fontsize=7)
    a2.set_ylabel("peak contact force [kN]")
    a2.grid(alpha=0.3, axis="y")
    return [save(fig, fig_dir / "thesis_comparison.png")]


STUDY = Study(
    name="thesis",
    help=("thesis comparison: the thesis's mode count and band, and the drop of the "
          "wheelset"),
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    sorted_settings=("drop_heights", "contact_damping"),
    needs_track="it compares the vehicle's passage on the track's modes with the thesis",
)
