"""Boundary reflection: the same train and building in larger and larger soil domains.

Defaults follow the thesis's own labels (section 6.7): its Model 1 has a 3 m deep subgrade,
Model 2 a 5 m deep one and Model 3 adds 2 m of length and 6 m of width beyond the building
to Model 2. Here ``model1`` is the case's domain with the fixed base raised to a 3 m deep
subgrade (``geometry.z0`` up by 1.8 m: 0.6 m below the 2.4 m-deep building base),
``model2`` is the case's domain itself (the APDL's 4.8 m subgrade, the thesis's "5 m"),
``model3`` adds 2 m of length at both ends (``domain.extra_length``, track unchanged) and
6 m of width beyond the building (``domain.extra_width``), and a larger domain (+4 m depth,
+4 m length, +12 m width) is the reference. Each domain has its own mesh and modes (the
fixed base and the roller sides move). A negative first entry of a domain (its depth
change) raises the base; a positive one deepens the subgrade (``domain.extra_depth``).

``boundaries`` adds the condition of the truncation faces as a dimension: every domain is run
with each setting (``case``: the case file's ``[boundary]``; ``thesis``: rollers and a fixed
base; ``absorbing``: Lysmer-Kuhlemeyer dashpots on all five faces; ``pml``: perfectly
matched layers of ``pml_thickness`` on all five faces, outside the domain, with the
case's engine) and compared
with the largest domain of the same setting.
``solver = direct`` runs every variant with the full-order time integration
(``railvib transient``) instead of modes + multibody.

Compared: the building peak accelerations (vertical and total) and their one-third-octave
spectra (1–80 Hz, total acceleration). Verdict: boundary reflections matter when the case's
own domain (the one with no change; otherwise the first) differs from the reference by more
than ``threshold`` percent in any building peak acceleration. With ``band_hz = 0`` every
domain keeps the case's number of modes, so larger domains end at lower frequencies
(listed); ``band_hz > 0`` gives every domain exactly its modes below that frequency instead
(``modal.f_max = band_hz``: the band-sliced eigensolve, whose inertia counts prove the
count; the MBS uses them all).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..boundary_registry import BOUNDARY_KINDS, boundary_kind
from ..config import Case
from ..schema import BOUNDARY_FACES
from .common import StudyPlan, Variant, all_with_contact_force, relative, response_quantities
from .protocol import Study
from .report import figure, fmt, pct, save, transpose

TITLE = "Boundary reflection study"


def weyl_count(case: Case, f_hz: float) -> float:
    """Weyl estimate of the number of modes below ``f_hz`` of the soil block
    (:func:`railvib_hpc.assess.thesis.weyl_count`): ``N(f) = (4 pi / 3) V f^3 (1 / c_P^3 +
    2 / c_S^3)`` with the soil box volume ``V`` and the subgrade wave speeds. On the
    refined layout of the thesis model it gives 99 below 30 Hz (118 computed) and 286 below
    42.7 Hz (300 computed).
    """
    from ..assess.thesis import weyl_count as _weyl

    return _weyl(case, f_hz)


def domain_overrides(case: Case, change: tuple[float, float, float]) -> list[str]:
    """Case overrides of a domain ``(depth, length, width)`` change relative to the case.

    A depth change below the case's own extra depth raises the fixed base
    (``geometry.z0``); the others add to ``domain.extra_*``.
    """
    d, ln, w = change
    base = case["domain"]
    depth = base["extra_depth"] + d
    out = []
    if case["site.soil_depth"] > 0:      # the base it set, given now (the variant's own)
        out += ["site.soil_depth=0.0", f"geometry.z0={case['geometry.z0']!r}"]
    if depth < 0.0:
        out.append(f"geometry.z0={case['geometry.z0'] - depth!r}")
        depth = 0.0
    return out + [f"domain.extra_depth={depth!r}",
                  f"domain.extra_length={base['extra_length'] + ln!r}",
                  f"domain.extra_width={base['extra_width'] + w!r}"]


#: Overrides of the boundary settings of the study (``boundaries``) that are no boundary
#: kind: the case's own faces and the thesis's.
SETTING_OVERRIDES = {
    "case": (),
    "thesis": ("boundary.x_min=roller", "boundary.x_max=roller", "boundary.y_min=roller",
               "boundary.y_max=roller", "boundary.base=fixed"),
}


def variant_kinds() -> list[str]:
    """The boundary kinds the study offers on all five faces (those whose
    :attr:`~railvib_hpc.model.boundary_kind.BoundaryKind.reflection_variant` is set)."""
    return [name for name in BOUNDARY_KINDS if boundary_kind(name).reflection_variant]


def boundary_overrides(setting: str) -> tuple[str, ...]:
    """The overrides of one boundary setting: the case's or the thesis's faces
    (:data:`SETTING_OVERRIDES`), or a kind on all five faces with the kind's own further
    overrides (the perfectly matched layers' lumped mass; their thickness is added outside
    each domain, :func:`pml_overrides`)."""
    if setting in SETTING_OVERRIDES:
        return SETTING_OVERRIDES[setting]
    kind = boundary_kind(setting)
    return (*(f"boundary.{f}={setting}" for f in BOUNDARY_FACES), *kind.reflection_overrides)


def pml_overrides(case: Case, change: tuple[float, float, float], thickness: float
                  ) -> list[str]:
    """The overrides of a domain with perfectly matched layers of ``thickness`` on its five
    faces: the layers lie outside the domain ``change`` (it keeps its size), so the soil
    grows by ``thickness`` at the base, at both ends, beyond the building and on the far
    side of the track (``geometry.ys0``)."""
    d, ln, w = change
    return [*domain_overrides(case, (d + thickness, ln + thickness, w + thickness)),
            f"geometry.ys0={case['geometry.ys0'] + thickness!r}",
            f"boundary.layer_thickness={float(thickness)!r}"]


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """One variant per boundary setting and domain (own mesh and modes, or the direct
    solution with ``solver = direct``). With one boundary setting the variants are named
    after the domains, otherwise ``<boundary>-<domain>``."""
    from .settings import StudySettingsError

    variants = []
    direct = settings.get("solver", "modal") == "direct"
    band = 0.0 if direct else settings["band_hz"]
    lowest = -(case["geometry.zbb"] - case["geometry.z0"]) - case["domain.extra_depth"]
    bad = [dom for dom in settings["domains"] if dom[0] <= lowest]
    if bad:
        raise StudySettingsError("reflection", [(
            "study.reflection.domains", settings["domains"],
            f"the depth changes {[dom[0] for dom in bad]} m raise the fixed base to or above "
            f"the building base (z = {case['geometry.zbb']:g} m): a depth change must be "
            f"> {lowest:g} m")])
    boundaries = settings.get("boundaries", ["case"])
    kinds = {b: boundary_kind(b) for b in boundaries if b in BOUNDARY_KINDS}
    time_domain = [b for b, kind in kinds.items() if not kind.modal]
    if time_domain and not direct:
        raise StudySettingsError("reflection", [(
            "study.reflection.boundaries", boundaries,
            f"'{time_domain[0]}' needs study.reflection.solver = 'direct' "
            f"({kinds[time_domain[0]].time_domain_note}: railvib transient)")])
    for b in boundaries:
        outside = b in kinds and kinds[b].reflection_layer_outside
        for name, (d, ln, w) in zip(settings["names"], settings["domains"]):
            ov = [*(pml_overrides(case, (d, ln, w), settings["pml_thickness"]) if outside
                    else domain_overrides(case, (d, ln, w))), *boundary_overrides(b)]
            if band > 0:
                # every mode below the band, proved by the inertia counts of the band solve
                ov += [f"modal.f_max={float(band)!r}"]
            variants.append(Variant(name=name if len(boundaries) == 1 else f"{b}-{name}",
                                    overrides=tuple(ov),
                                    parameter={"boundary": b, "extra_depth": d,
                                               "extra_length": ln, "extra_width": w},
                                    band_hz=band))
    return StudyPlan("reflection", tuple(variants))


def _only_acc(q: dict[str, float]) -> dict[str, float]:
    return {k: v for k, v in q.items() if k != "peak contact force"}


def spectrum_difference_db(spec: dict, ref: dict, floor: float = 0.1) -> float | None:
    """Largest band difference |20 log10(S / S_ref)| [dB] of total-acceleration spectra,
    over the bands where the reference exceeds ``floor`` times its largest band."""
    if not spec or not ref:
        return None
    common = sorted(set(spec["bands_hz"]) & set(ref["bands_hz"]))
    if not common:
        return None
    s = dict(zip(spec["bands_hz"], spec["acc_rms"]["total"]))
    r = dict(zip(ref["bands_hz"], ref["acc_rms"]["total"]))
    rmax = max(r[b] for b in common)
    diffs = [abs(20 * math.log10(s[b] / r[b])) for b in common
             if r[b] >= floor * rmax and r[b] > 0 and s[b] > 0]
    return max(diffs) if diffs else None


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """Peaks and spectra of every domain against the reference (the last domain of the same
    boundary setting)."""
    groups: dict[str, list] = {}
    for v in plan_.variants:
        groups.setdefault(v.parameter.get("boundary", "case"), []).append(v)
    data, dtables, verdicts = [], [], []
    names = None
    for boundary, variants in groups.items():
        done = [v for v in variants if v.name in results]
        if len(done) < 2:
            continue
        ref = done[-1]
        qref = response_quantities(results[ref.name], settings["probes"])
        names = list(_only_acc(qref))
        rows = []
        for i, v in enumerate(done):
            r = results[v.name]
            q = response_quantities(r, settings["probes"])
            qprev = response_quantities(results[done[i - 1].name], settings["probes"]) \
                if i else None
            dev = {k: relative(q[k], qref[k]) for k in names}
            step = {k: relative(q[k], qprev[k]) for k in names} if qprev else {}
            sdb = {p: spectrum_difference_db(r["spectra"].get(p), results[ref.name]["spectra"]
                                             .get(p)) for p in settings["probes"]}
            rows.append({"variant": v.name, "boundary": boundary, **v.parameter,
                         "n_nodes": r["model"]["n_nodes"], "n_dofs": r["model"]["n_dofs"],
                         "modes": r["model"]["modes_used"], "band_hz": r["model"]["f_max_hz"],
                         "f1_hz": r["model"]["frequencies_hz"][0], "quantities": q,
                         "deviation": dev, "step": step,
                         "max_deviation": max((x for x in dev.values() if x is not None),
                                              default=None),
                         "max_step": max((x for x in step.values() if x is not None),
                                         default=None),
                         "spectrum_db": sdb, "wall_s": r["timings"]["total"]})
        data.extend(rows)
        complete_ref = ref.name == variants[-1].name
        verdicts.append(_verdict(rows, ref, settings, complete_ref, boundary,
                                 len(groups) > 1))
        drows = [[d["variant"], *(pct(d["deviation"][k]) for k in names),
                  pct(d["max_deviation"]), pct(d["max_step"])] for d in rows]
        dtables.append({"title": f"Difference from the reference domain {ref.name}",
                        **dict(zip(("head", "rows"), transpose(
                            ["domain", *names, "max vs reference", "max vs previous domain"],
                            drows)))})
    if not verdicts:
        return {"title": TITLE, "verdict": {"text": "fewer than 2 domains of any boundary "
                                            "setting finished; need 2", "ok": None},
                "tables": [], "rows": []}
    # the contact force of a vehicle; none without a track (the moving load of [load])
    force = all_with_contact_force(data)
    head = ["domain", "boundary", "+depth [m]", "+length [m]", "+width [m]", "nodes", "DOFs",
            "modes", "band [Hz]", "f1 [Hz]", *names,
            *(["peak contact force"] if force else [])]
    rows = [[d["variant"], d["boundary"], fmt(d["extra_depth"]), fmt(d["extra_length"]),
             fmt(d["extra_width"]), fmt(d["n_nodes"]), fmt(d["n_dofs"]), fmt(d["modes"]),
             fmt(d["band_hz"]), fmt(d["f1_hz"]), *(fmt(d["quantities"][k]) for k in names),
             *([fmt(d["quantities"]["peak contact force"])] if force else [])] for d in data]
    srows = [[d["variant"], *(fmt(d["spectrum_db"][p], 3) for p in settings["probes"])]
             for d in data]
    direct = settings.get("solver", "modal") == "direct"
    tables = [
        {"title": "Domains and peak responses",
         **dict(zip(("head", "rows"), transpose(head, rows))),
         "note": "Accelerations in m/s² (a_z vertical, |a| total peak)"
                 + (", contact force in N; " if force else " (no contact force: no vehicle); ")
                 + ("solver: direct time integration of the full model (band: "
                    "transient.f_max, no modes)." if direct else
                    "band: frequency of the highest mode used, f1: lowest natural "
                    "frequency.")},
        *dtables,
        {"title": "One-third-octave spectra: largest band difference from the reference [dB]",
         "head": ["domain", *settings["probes"]], "rows": srows,
         "note": "Total acceleration, bands 1–80 Hz where the reference exceeds 10 % of its "
                 "largest band."},
    ]
    verdict = dict(verdicts[0])
    if len(verdicts) > 1:
        verdict["text"] = "; ".join(v["text"] for v in verdicts)
        verdict["ok"] = all(v["ok"] for v in verdicts)
        verdict["groups"] = verdicts
    return {"title": TITLE, "verdict": verdict, "tables": tables, "rows": data,
            "reference": verdicts[0]["reference"]}


def _verdict(data: list, ref: Variant, settings: dict, complete_ref: bool,
             boundary: str = "case", named: bool = False) -> dict:
    thr = settings["threshold"] / 100.0
    own = [d for d in data[:-1] if (d["extra_depth"], d["extra_length"], d["extra_width"])
           == (0.0, 0.0, 0.0)]
    first = own[0] if own else data[0]
    dev = first["max_deviation"]
    worst = max(first["deviation"], key=lambda k: first["deviation"][k] or 0.0)
    matters = dev is not None and dev > thr
    text = ((f"with {boundary} boundaries: " if named else "")
            + f"boundary reflections {'MATTER' if matters else 'do not matter'} for the "
            f"{first['variant']} domain: its building peak accelerations differ from the "
            f"reference domain {ref.name} by up to {100 * (dev or 0):.2f} % ({worst}; "
            f"threshold {settings['threshold']:g} %)")
    ok_from = next((d["variant"] for d in data[:-1]
                    if all((x or 0.0) <= thr for x in d["deviation"].values())), None)
    if matters:
        text += (f"; {ok_from} is within the threshold" if ok_from else
                 "; no smaller domain is within the threshold")
    if not complete_ref:
        text += " [the planned reference domain has not finished]"
    return {"text": text, "ok": not matters, "reflections_matter": matters,
            "max_deviation": dev, "governing": worst, "threshold_percent": settings["threshold"],
            "within_threshold_from": ok_from, "boundary": boundary, "reference": ref.name}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """Peak accelerations per domain (bars) and the total-acceleration spectra."""
    data = analysis.get("rows") or []
    if not data:
        return []
    probes = settings["probes"]
    out = []
    fig = figure(figsize=(11, 4.5))
    axes = fig.subplots(1, 2)
    x = np.arange(len(probes))
    width = 0.8 / len(data)
    for ax, comp, title in ((axes[0], "a_z", "peak vertical acceleration"),
                            (axes[1], "|a|", "peak total acceleration")):
        for i, d in enumerate(data):
            ax.bar(x + i * width, [d["quantities"][f"{p} {comp}"] for p in probes], width,
                   label=d["variant"])
        ax.set_xticks(x + 0.4 - width / 2, probes, fontsize=8)
        ax.set_ylabel("m/s²")
        ax.set_title(title)
        ax.grid(alpha=0.3, axis="y")
        ax.legend(fontsize=7)
    out.append(save(fig, fig_dir / "reflection_peaks.png"))
    fig = figure(figsize=(11, 7))
    axes = fig.subplots(2, 2).ravel()
    for ax, p in zip(axes, probes[:4]):
        for d in data:
            s = ((results or {}).get(d["variant"]) or {}).get("spectra", {}).get(p)
            if s:
                ax.semilogy(s["bands_hz"], s["acc_rms"]["total"], "o-", ms=3, lw=1,
                            label=d["variant"])
        ax.set_xscale("log")
        ax.set_xlabel("one-third-octave band [Hz]")
        ax.set_ylabel("RMS acceleration [m/s²]")
        ax.set_title(p)
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    for ax in axes[len(probes[:4]):]:
        ax.set_visible(False)
    out.append(save(fig, fig_dir / "reflection_spectra.png"))
    return out


def derive_settings(settings: dict[str, Any], given: dict[str, Any]) -> None:
    """Domains given without their names: ``domain1``, ``domain2``, ... (in place)."""
    if "domains" in given and "names" not in given:
        settings["names"] = [f"domain{i + 1}" for i in range(len(settings["domains"]))]


STUDY = Study(
    name="reflection",
    help=("boundary reflections: the same train and building in larger and larger soil "
          "domains"),
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    derive_settings=derive_settings,
)
