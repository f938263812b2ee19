"""Mitigation: the baseline and each measure with everything else identical, ranked.

A measure is a name and case overrides, ``"name: key=value; key=value"`` (the values in
TOML syntax, as ``--set``), e.g. soft rail pads (``pads.kz``), an open or in-filled trench
(``[trench]``) or a wave-impeding block under the track (``[wib]``). Every measure runs as
its own variant (own mesh and modes where the measure changes them: the stage files of a
variant are reused on a rerun).

Reference of each measure: the ``baseline`` variant (the case itself), except for measures
that change the soil geometry (``trench.*``, ``wib.*``) when ``same_mesh`` is on: these are
compared with a reference variant that has the measure's mesh lines but no measure (type
``none`` with the same sizes), so that the insertion loss is the measure's and not the
mesh's (measures with the same geometry share one reference). The baseline's difference
from these references shows the mesh's own share (the table lists it).

Insertion loss (positive: the measure reduces the vibration), per building probe:

* per one-third-octave band (1–80 Hz, total acceleration, RMS over the record):
  ``IL = 20 log10(a_ref / a_measure)`` dB, the usual definition (e.g. ISO 14837-1);
* on the assessment metrics: the peak vertical and total accelerations, the same way;
* the assessment itself: the largest utilisation (value / limit of the binding standards of
  ``[assessment]``) before and after, and whether every probe passes.

Only the one-third-octave bands that both variants of a comparison resolve are reported
(the study runner cuts each variant's spectra at its highest mode used, see
:func:`~.common.resolved_spectra`). ``solver = direct`` runs every variant, the references
included, with the full-order time integration (``railvib transient``) instead of modes +
multibody.

Ranking: by the largest utilisation over the probes after the measure (lowest first: the
measure that brings the building furthest under the limits), ties by the mean insertion
loss on the peak total acceleration. Verdict: the best measure and the measures under which
every probe passes (or that none does).
"""

from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..config import Case, parse_override
from ..errors import CaseError
from .common import StudyPlan, Variant, response_quantities
from .protocol import Study
from .report import figure, fmt, save, transpose

TITLE = "Mitigation study"
#: Name of the variant that runs the case itself.
BASELINE = "baseline"
#: Case sections whose keys change the soil geometry (a measure with them gets a reference
#: on its own mesh when ``same_mesh`` is on), and the type that switches each off.
GEOMETRIC = {"trench": "trench.type=none", "wib": "wib.type=none"}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.+-]*$")


#: Case sections of the track and the train: a measure on them has nothing to act on in a
#: case without a track (``track.count = 0``).
TRACK_SECTIONS = ("track", "pads", "usp", "ballast_mat", "sections", "vehicle", "train2",
                  "irregularity", "mbs")


def trackless_problem(settings: dict[str, Any]) -> tuple[str, Any, str] | None:
    """The first measure that sets a key of the track or the train (:data:`TRACK_SECTIONS`),
    for a case without a track (None: every measure acts on the soil, the building or the
    load).

    Returns
    -------
    tuple or None
        ``(key, value, allowed)`` naming ``study.mitigation.measures`` and the measure.
    """
    for text in settings["measures"]:
        name, overrides = parse_measure(text)
        keys = [ov.split("=", 1)[0].strip() for ov in overrides]
        track = [k for k in keys if k.split(".", 1)[0] in TRACK_SECTIONS]
        if track:
            return ("study.mitigation.measures", text,
                    f"the measure {name!r} sets {', '.join(track)}, of the track or the "
                    "train; a case without a track (track.count = 0) has neither: give "
                    "measures in the soil or the building (e.g. 'trench: trench.type=open; "
                    "trench.distance=6; trench.width=0.6; trench.depth=3')")
    return None


def parse_measure(text: str) -> tuple[str, tuple[str, ...]]:
    """``"name: key=value; key=value"`` -> ``(name, ("key=value", ...))``.

    Raises
    ------
    CaseError
        Naming ``study.mitigation.measures`` and the entry when it is malformed.
    """
    key = "study.mitigation.measures"
    if ":" not in text:
        raise CaseError([(key, text, "each measure must look like 'name: key=value; "
                          "key=value' (e.g. 'soft_pads: pads.kz=1e8')")])
    name, rest = (x.strip() for x in text.split(":", 1))
    if not _NAME.match(name) or name == BASELINE or name.startswith("ref-"):
        raise CaseError([(key, text, f"the measure's name {name!r} must be letters, digits "
                          f"and '_.+-', and not '{BASELINE}' or start with 'ref-'")])
    overrides = tuple(x.strip() for x in rest.split(";") if x.strip())
    if not overrides:
        raise CaseError([(key, text, "the measure sets no key (give key=value after ':')")])
    for ov in overrides:
        if "=" not in ov:
            raise CaseError([(key, text, f"{ov!r} is not key=value")])
        parse_override(ov)
    return name, overrides


def _geometric(overrides: tuple[str, ...]) -> tuple[str, ...]:
    """The overrides of a measure that place soil geometry (``trench.*``, ``wib.*``)."""
    return tuple(ov for ov in overrides if ov.split("=", 1)[0].strip().split(".")[0]
                 in GEOMETRIC)


def reference_overrides(overrides: tuple[str, ...]) -> tuple[str, ...] | None:
    """The overrides of a geometric measure's reference: the same sizes, type ``none``
    (None for a measure that does not change the soil geometry)."""
    geo = _geometric(overrides)
    if not geo:
        return None
    sections = sorted({ov.split("=", 1)[0].strip().split(".")[0] for ov in geo})
    kept = tuple(ov for ov in geo if not ov.split("=", 1)[0].strip().endswith(".type"))
    return kept + tuple(GEOMETRIC[s] for s in sections)


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """The baseline, every measure, and the same-mesh references of the geometric ones."""
    from .settings import StudySettingsError

    measures = []
    for text in settings["measures"]:
        try:
            measures.append(parse_measure(text))
        except CaseError as exc:
            raise StudySettingsError("mitigation", exc.problems) from None
    names = [m[0] for m in measures]
    if len(set(names)) != len(names):
        raise StudySettingsError("mitigation", [("study.mitigation.measures", names,
                                                 "measure names must be distinct")])
    variants = [Variant(name=BASELINE, overrides=(), parameter={"measure": BASELINE,
                                                                "reference": None})]
    refs: dict[tuple[str, ...], str] = {}
    for name, overrides in measures:
        ref = BASELINE
        ref_ov = reference_overrides(overrides) if settings["same_mesh"] else None
        if ref_ov is not None:
            if ref_ov not in refs:
                refs[ref_ov] = f"ref-{name}"
                variants.append(Variant(name=refs[ref_ov], overrides=ref_ov,
                                        parameter={"measure": None, "reference": BASELINE}))
            ref = refs[ref_ov]
        variants.append(Variant(name=name, overrides=overrides,
                                parameter={"measure": name, "reference": ref}))
    return StudyPlan("mitigation", tuple(variants))


def insertion_loss_db(ref: float | None, value: float | None) -> float | None:
    """``20 log10(ref / value)`` [dB] (None when either is missing or not positive)."""
    if ref is None or value is None or not (ref > 0 and value > 0):
        return None
    return 20.0 * math.log10(ref / value)


def band_insertion_loss(ref: dict | None, spec: dict | None, component: str = "total"
                        ) -> dict[float, float]:
    """Insertion loss per one-third-octave band [dB] of two probe spectra (common bands)."""
    if not ref or not spec:
        return {}
    r = dict(zip(ref["bands_hz"], ref["acc_rms"][component]))
    s = dict(zip(spec["bands_hz"], spec["acc_rms"][component]))
    out = {}
    for band in sorted(set(r) & set(s)):
        il = insertion_loss_db(r[band], s[band])
        if il is not None:
            out[float(band)] = il
    return out


def _utilisation(result: dict, probes: list[str]) -> tuple[float | None, bool | None, str]:
    """Largest utilisation over the probes, whether all pass, and the governing probe."""
    ass = {p: result["assessment"][p] for p in probes if p in result["assessment"]}
    utils = {p: a["max_utilisation"] for p, a in ass.items() if a["max_utilisation"] is not None}
    passed = [a["passed"] for a in ass.values()]
    gov = max(utils, key=utils.get) if utils else "–"
    ok = False if False in passed else None if (None in passed or not passed) else True
    return (max(utils.values()) if utils else None), ok, gov


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """Insertion losses, the assessment before and after, and the ranking."""
    probes = settings["probes"]
    rows = []
    for v in plan_.variants:
        m = v.parameter.get("measure")
        ref = v.parameter.get("reference")
        if m in (None, BASELINE) or v.name not in results or ref not in results:
            continue
        r, b = results[v.name], results[ref]
        q, qb = response_quantities(r, probes), response_quantities(b, probes)
        il_peak = {k: insertion_loss_db(qb[k], q[k]) for k in q if k != "peak contact force"}
        il_band = {p: band_insertion_loss(b["spectra"].get(p), r["spectra"].get(p))
                   for p in probes}
        u_after, ok_after, gov = _utilisation(r, probes)
        u_before, ok_before, _ = _utilisation(b, probes)
        total = [x for k, x in il_peak.items() if k.endswith("|a|") and x is not None]
        rows.append({"measure": m, "variant": v.name, "reference": ref,
                     "overrides": list(v.overrides), "il_peak_db": il_peak,
                     "il_band_db": {p: {str(f): x for f, x in d.items()}
                                    for p, d in il_band.items()},
                     "mean_il_total_db": float(np.mean(total)) if total else None,
                     "min_il_total_db": min(total) if total else None,
                     "utilisation_before": u_before, "utilisation_after": u_after,
                     "passed_before": ok_before, "passed_after": ok_after,
                     "governing_probe": gov,
                     "peak_contact_force": q.get("peak contact force"),   # None: no track
                     "wall_s": r["timings"]["total"]})
    if not rows:
        return {"title": TITLE, "verdict": {"text": "no measure finished together with its "
                                            "reference", "ok": None}, "tables": [], "rows": []}

    def rank_key(d: dict) -> tuple:
        u = d["utilisation_after"]
        return (u is None, u if u is not None else 0.0, -(d["mean_il_total_db"] or -1e9))

    rows.sort(key=rank_key)
    for k, d in enumerate(rows):
        d["rank"] = k + 1
    verdict_ = {True: "pass", False: "FAIL", None: "undetermined"}
    ranked = [[str(d["rank"]), d["measure"], d["reference"], fmt(d["mean_il_total_db"], 3),
               fmt(d["min_il_total_db"], 3), fmt(d["utilisation_before"], 3),
               fmt(d["utilisation_after"], 3), verdict_[d["passed_after"]],
               d["governing_probe"]] for d in rows]
    keys = [k for k in rows[0]["il_peak_db"]]
    peaks = [[d["measure"], *(fmt(d["il_peak_db"][k], 3) for k in keys)] for d in rows]
    bands = sorted({float(f) for d in rows for p in probes for f in d["il_band_db"][p]})
    mean_band = []
    for d in rows:
        vals = []
        for f in bands:
            xs = [d["il_band_db"][p][str(f)] for p in probes if str(f) in d["il_band_db"][p]]
            vals.append(fmt(float(np.mean(xs)), 3) if xs else "–")
        mean_band.append([d["measure"], *vals])
    tables = [
        {"title": "Measures ranked", "head": ["rank", "measure", "reference",
                                              "mean IL, peak |a| [dB]", "min IL, peak |a| [dB]",
                                              "utilisation before", "utilisation after",
                                              "assessment after", "governing probe"],
         "rows": ranked,
         "note": "IL = 20 log10(reference / measure): positive reduces. Utilisation: the "
                 "largest value/limit of the binding standards over the probes (≤ 1 "
                 "passes). Ranked by the utilisation after the measure, then the mean IL."},
        {"title": "Insertion loss on the peak accelerations [dB]",
         **dict(zip(("head", "rows"), transpose(["measure", *keys], peaks)))},
        {"title": "Insertion loss per one-third-octave band [dB], mean over the probes",
         "head": ["measure", *(f"{f:g} Hz" for f in bands)], "rows": mean_band,
         "note": "Total acceleration, RMS over the record, 1–80 Hz: only the bands both "
                 "variants resolve (up to their highest mode used, or transient.f_max with "
                 "solver = direct; see 'Frequency band of each variant')."},
    ]
    mesh_share = _mesh_share(plan_, results, probes)
    if mesh_share:
        tables.append({"title": "Mesh share: the same-mesh references against the baseline",
                       "head": ["reference", "mean |IL|, peak |a| [dB]"],
                       "rows": [[k, fmt(x, 3)] for k, x in mesh_share.items()],
                       "note": "The references differ from the baseline by the measure's mesh "
                               "lines only (no measure): the discretisation's share of an "
                               "insertion loss computed against the baseline."})
    return {"title": TITLE, "verdict": _verdict(rows, results.get(BASELINE), probes),
            "tables": tables, "rows": rows, "mesh_share_db": mesh_share}


def _mesh_share(plan_: StudyPlan, results: dict, probes: list[str]) -> dict[str, float]:
    if BASELINE not in results:
        return {}
    qb = response_quantities(results[BASELINE], probes)
    out = {}
    for v in plan_.variants:
        if v.parameter.get("measure") is None and v.name in results:
            q = response_quantities(results[v.name], probes)
            ils = [abs(insertion_loss_db(qb[k], q[k]) or 0.0) for k in q if k.endswith("|a|")]
            out[v.name] = float(np.mean(ils)) if ils else None
    return out


def _verdict(rows: list[dict], baseline: dict | None, probes: list[str]) -> dict:
    best = rows[0]
    passing = [d["measure"] for d in rows if d["passed_after"] is True]
    text = (f"best measure: {best['measure']} (largest utilisation "
            f"{fmt(best['utilisation_before'], 3)} -> {fmt(best['utilisation_after'], 3)}, "
            f"mean insertion loss {fmt(best['mean_il_total_db'], 3)} dB on the peak total "
            "acceleration); ")
    if baseline is not None:
        u, ok, gov = _utilisation(baseline, probes)
        text += (f"the baseline {'passes' if ok else 'FAILS' if ok is False else 'is undetermined'}"
                 f" (largest utilisation {fmt(u, 3)} at {gov}); ")
    text += ("every probe passes with: " + ", ".join(passing) if passing
             else "no measure brings every probe under the limits")
    return {"text": text, "ok": bool(passing), "best": best["measure"], "passing": passing,
            "ranking": [d["measure"] for d in rows]}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """Insertion loss against frequency, one panel per probe, one line per measure."""
    rows = analysis.get("rows") or []
    if not rows:
        return []
    probes = settings["probes"][:4]
    fig = figure(figsize=(11, 7))
    axes = np.atleast_1d(fig.subplots(2, 2)).ravel()
    for ax, p in zip(axes, probes):
        for d in rows:
            il = d["il_band_db"].get(p) or {}
            f = sorted(float(x) for x in il)
            ax.semilogx(f, [il[str(x)] for x in f], "o-", ms=3, lw=1, label=d["measure"])
        ax.axhline(0.0, color="k", lw=0.6)
        ax.set_xlabel("one-third-octave band [Hz]")
        ax.set_ylabel("insertion loss [dB]")
        ax.set_title(p)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    for ax in axes[len(probes):]:
        ax.set_visible(False)
    return [save(fig, fig_dir / "mitigation_insertion_loss.png")]


STUDY = Study(
    name="mitigation",
    help=("mitigation: the baseline and each measure with everything else identical, "
          "ranked"),
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    trackless_problem=trackless_problem,
)
