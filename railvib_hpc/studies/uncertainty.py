"""Uncertainty: the case's uncertain inputs sampled, each sample a variant, and statistics.

The inputs are the case's ``[uncertainty]`` tables (:mod:`railvib_hpc.uncertain_inputs`):
distributions of case keys (``[[uncertainty.parameter]]``, correlated through a Gaussian
copula) and random fields of the soil layers (``[[uncertainty.field]]``). The design
(:mod:`railvib_hpc.uncertainty.sampling`, ``uncertainty.method``: ``lhs``, ``mc`` or
``sobol``) is drawn from ``uncertainty.seed``: sample ``k`` is the variant ``s<k>`` with
the sampled keys as overrides (a layer's entries as one ``soil.layers`` override) and, with
fields, ``uncertainty.realisation = k + 1``; the design itself is taken out of the sample's
case (:data:`DESIGN_RESET`), so growing an ``mc`` or ``sobol`` design later reuses the
samples already finished. Every variant builds its own model; the study
resumes, runs as an array (``--variant``) and merges (``--merge``) like the others.

Analysis, per building probe (``probes``) and per standard of ``[assessment]``:

* P5, P50, P95 of the standard's metric in its governing direction (ISO 2631 weighted
  RMS/MTVV, DIN 4150-2 KB_F, DIN 4150-3 PPV, FTA VdB, the VC one-third-octave velocity),
  with percentile-bootstrap intervals;
* the probability of exceeding the limit (utilisation > 1) with its Wilson interval;
* with ``sobol``: first-order and total Sobol' indices of the probe's peak total
  acceleration and largest utilisation (SALib), i.e. which input drives each probe;
* the convergence of P50, P95 and the exceedance probability with the sample count.

While the samples run, rank 0 prints the statistics of the samples so far after each one
(:func:`progress`). The merge writes ``report.md``/``report.json`` and ``uncertainty.h5``
(the design, the sampled values and every output per sample).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..assess.standards import BUILDING_USES
from ..config import Case
from ..io.digests import digest
from ..uncertain_inputs import LAYER_KEY, marginals
from ..uncertainty.sampling import saltelli_base_rows, sample_values
from ..uncertainty.statistics import (
    MIN_SOBOL_BASE_SAMPLES,
    convergence,
    exceedance,
    percentiles,
    sobol_doubts,
    sobol_indices,
)
from .common import StudyPlan, Variant
from .protocol import Study
from .report import figure, fmt, pct, save

TITLE = "Uncertainty study"
#: The outputs of the Sobol' indices and the convergence table, per probe.
OUTPUTS = ("peak |a|", "max utilisation")
#: Overrides that take the design out of every sample's case (it is a plain case of the
#: sampled values; the fields, the seed and the realisation stay): a sample's digest is
#: that of its own inputs, so a design grown later (``mc``, ``sobol``: the first samples
#: stay the same) reuses the samples already finished.
DESIGN_RESET = ("uncertainty.parameter=[]", "uncertainty.correlation=[]",
                'uncertainty.method="lhs"', "uncertainty.samples=1")


def _toml(v: Any) -> str:
    """A number or a table of numbers in TOML syntax (for an override)."""
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml(x)}" for k, x in v.items()) + "}"
    return repr(float(v)) if isinstance(v, float) else repr(v)


def sample_overrides(case: Case, keys: list[str], row: np.ndarray) -> tuple[str, ...]:
    """The case overrides of one sample: plain keys as ``key=value``, the layers' entries
    merged into one ``soil.layers=[...]``."""
    out, layers = [], None
    for key, value in zip(keys, row):
        m = LAYER_KEY.match(key)
        if m:
            layers = layers or [dict(x) for x in case["soil.layers"]]
            layers[int(m.group(1)) - 1][m.group(2)] = float(value)
        else:
            out.append(f"{key}={float(value)!r}")
    if layers is not None:
        out.append("soil.layers=[" + ", ".join(_toml(x) for x in layers) + "]")
    return tuple(out)


def design(case: Case) -> tuple[list, np.ndarray]:
    """The marginals and the sampled values ``(rows, d)`` of the case's design."""
    found = marginals(case)
    corr = case["uncertainty.correlation"]
    values = sample_values(found, case["uncertainty.method"], case["uncertainty.samples"],
                           case["uncertainty.seed"], np.asarray(corr) if corr else None) \
        if found else np.zeros((case["uncertainty.samples"], 0))
    return found, values


#: :func:`plan` takes the study's folder (the reduced model's basis is a file in it).
PLAN_IN_FOLDER = True
#: The reduced model's basis holds this many times ``modal.n_modes`` nominal modes (with
#: their sensitivity vectors): the samples' modes move, and the higher nominal modes hold
#: what the lower ones move towards (measured: docs/uncertainty.md, 'The reduced model').
NOMINAL_MODES_FACTOR = 2
#: Seed offset of the reference samples' draw (independent of the design's stream).
REFERENCE_SEED_OFFSET = 7919


def reference_samples(n: int, count: int, seed: int) -> list[int]:
    """The samples also solved in full to check the reduced model: ``count`` of the ``n``
    drawn at random without replacement (seeded), sorted."""
    rng = np.random.default_rng([seed, REFERENCE_SEED_OFFSET])
    return sorted(rng.choice(n, size=min(count, n), replace=False).tolist())


def varied_parts(case: Case) -> dict[str, tuple[str, ...]]:
    """The model parts a reduced model needs sensitivity vectors for: ``{part: ("K",) or
    ("K", "M")}`` from the uncertain keys and fields (layers: ``soil_layer_<k>``; a
    layer's rho changes its E too when it gives c_s)."""
    out: dict[str, set] = {}
    for entry in case["uncertainty.parameter"]:
        key = entry["key"]
        m = LAYER_KEY.match(key)
        if m:
            name = m.group(2)
            which = {"c_s": "K", "E": "K", "nu": "K", "rho": "KM"}.get(name, "")
            if which:
                out.setdefault(f"soil_layer_{m.group(1)}", set()).update(which)
        elif key.startswith("pads.k"):
            out.setdefault(f"pad_{key[-1]}", set()).add("K")
        elif key.startswith("materials."):
            _, mat, name = key.split(".")
            out.setdefault(mat, set()).update({"E": "K", "nu": "K", "rho": "M"}.get(name, ""))
    for f in case["uncertainty.field"]:
        out.setdefault(f"soil_layer_{f['layer']}", set()).add(
            "K" if f["quantity"] == "E" else "M")
    return {k: tuple(sorted(v)) for k, v in sorted(out.items()) if v}


def prepare(plan_: StudyPlan, case: Case, root: Path, comm, rep) -> None:
    """With the reduced model: the nominal model (``<root>/model``) and its basis
    (collective)."""
    info = plan_.info.get("reduced")
    if not info:
        return
    from ..modal.reduced import prepare_basis
    from ..parallel import on_root
    from ..problem import Problem
    from .common import prepare_shared, variant_case

    prepare_shared(plan_, case, root, comm, rep)
    mcase = on_root(lambda: variant_case(case, plan_.shared_overrides), comm)
    prepare_basis(Problem.from_case(mcase), Path(info["basis"]), comm, rep,
                  {k: tuple(v) for k, v in info["varied"].items()},
                  lowest=case["modal.n_modes"])


def _samples(plan_: StudyPlan) -> list[Variant]:
    """The design's samples (without the reduced model's reference solves)."""
    return [v for v in plan_.variants if not v.parameter.get("reference")]


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """One variant per sample of the design (own model each; with the reduced model, the
    nominal model's basis, and the reference samples ``r<k>`` after them)."""
    from ..modal.reduced import BASIS_H5, SENSITIVITY_DEPTH
    from ..uncertainty.reduced import REDUCED_TOL
    from .common import SHARED_DIR
    from .settings import StudySettingsError

    found, values = design(case)
    fields = bool(case["uncertainty.field"])
    if not found and not fields:
        raise StudySettingsError("uncertainty", [(
            "uncertainty.parameter", [], "the case has no [[uncertainty.parameter]] nor "
            "[[uncertainty.field]]: nothing is uncertain (see docs/uncertainty.md)")])
    if case["uncertainty.model"] == "reduced" and settings.get("solver") == "direct":
        raise StudySettingsError("uncertainty", [(
            "study.uncertainty.solver", "direct", "the reduced model (uncertainty.model = "
            "'reduced') reduces the modal solve: use solver = 'modal', or model = 'full'")])
    keys = [m.key for m in found]
    width = max(4, len(str(len(values) - 1)))
    reduced = case["uncertainty.model"] == "reduced"
    extra: tuple[str, ...] = ()
    # the nominal model: without the design and the reduced model's own keys (a changed
    # tolerance keeps the nominal modes and the basis)
    shared = (*DESIGN_RESET, f"modal.n_modes={NOMINAL_MODES_FACTOR * case['modal.n_modes']}",
              f"uncertainty.reduced_tol={REDUCED_TOL!r}", "uncertainty.reduced_checks=0")
    if reduced:          # the basis's name holds its inputs: another basis, other digests
        tag = digest({"shared": shared, "varied": varied_parts(case),
                      "depth": SENSITIVITY_DEPTH, "lowest": case["modal.n_modes"]})[:12]
        basis = (Path(root or ".") / SHARED_DIR / BASIS_H5.format(tag=tag)).resolve()
        extra = (f"uncertainty.basis={json.dumps(str(basis))}",)
    variants, refs = [], []
    checks = reference_samples(len(values), case["uncertainty.reduced_checks"],
                               case["uncertainty.seed"]) if reduced else []
    for k, row in enumerate(values):
        ov = DESIGN_RESET + sample_overrides(case, keys, row) + extra
        if fields:
            ov = (*ov, f"uncertainty.realisation={k + 1}")
        par = {"sample": k, **{m.name: float(x) for m, x in zip(found, row)}}
        variants.append(Variant(name=f"s{k:0{width}d}", overrides=ov, parameter=par))
        if k in checks:
            refs.append(Variant(name=f"r{k:0{width}d}", overrides=(
                *ov, "uncertainty.reference=true"), parameter={**par, "reference": True}))
    info = {"method": case["uncertainty.method"], "parameters": [m.name for m in found],
            "vc_class": BUILDING_USES[case["assessment.building_use"]]["vc"]}
    if reduced:
        info["reduced"] = {"varied": varied_parts(case), "basis": str(basis),
                           "tol": case["uncertainty.reduced_tol"],
                           "references": {r.name: f"s{r.parameter['sample']:0{width}d}"
                                          for r in refs}}
    return StudyPlan("uncertainty", tuple(variants + refs), info=info,
                     shared_overrides=shared if reduced else None)


def listing_columns(plan_: StudyPlan, case: Case, entries: list[dict]
                    ) -> tuple[list[str], list[str], list[list[str]]]:
    """``--list``'s columns: one per sampled parameter (its value in the sample), the field
    realisation with random fields, and which sample a reference solve checks; the lines
    above the table name each parameter's key and distribution (the design's own keys,
    :data:`DESIGN_RESET`, are left out: every sample has them)."""
    names = _names(plan_)
    keys = {m.name: (m.key, m.distribution) for m in marginals(case)}
    notes = [f"{len(_samples(plan_))} samples (method {plan_.info['method']}) of "
             f"{len(names)} parameter{'s' if len(names) != 1 else ''}:"]
    notes += [f"  {n}: {keys[n][0]}, {keys[n][1]}" if n in keys else f"  {n}" for n in names]
    fields = bool(case["uncertainty.field"])
    refs = {r: s for r, s in (plan_.info.get("reduced") or {}).get("references", {}).items()}
    head = [*names, *(["realisation"] if fields else []), *(["checks"] if refs else [])]
    by_name = {v.name: v for v in plan_.variants}
    cells = []
    for e in entries:
        par = by_name[e["name"]].parameter
        row = [f"{par[n]:.6g}" for n in names]
        if fields:
            row.append(str(par["sample"] + 1))
        if refs:
            row.append(f"full solve of {refs[e['name']]}" if e["name"] in refs else "")
        cells.append(row)
    return notes, head, cells


def _names(plan_: StudyPlan) -> list[str]:
    return list(plan_.info.get("parameters") or [])


def outputs(plan_: StudyPlan, results: dict[str, dict], probes: list[str]) -> dict:
    """Every output per sample (NaN where a sample has not finished or gives none).

    Returns
    -------
    dict
        ``{probe: {"peak |a|": array, "max utilisation": array, standard: {"value": array,
        "utilisation": array, "metric", "unit", "limit"}}}`` in plan order.
    """
    samples = _samples(plan_)
    n = len(samples)
    out: dict[str, dict] = {}
    for p in probes:
        d: dict[str, Any] = {q: np.full(n, np.nan) for q in OUTPUTS}
        for i, v in enumerate(samples):
            r = results.get(v.name)
            if r is None:
                continue
            d["peak |a|"][i] = r["probes"][p]["acc_total"]
            a = r["assessment"].get(p) or {}
            d["max utilisation"][i] = _num(a.get("max_utilisation"))
            for s, m in (a.get("metrics") or {}).items():
                e = d.setdefault(s, {"value": np.full(n, np.nan), "utilisation":
                                     np.full(n, np.nan), "metric": m["metric"],
                                     "unit": m["unit"], "limits": [],
                                     "comparison_only": m["comparison_only"]})
                e["value"][i] = _num(m["value"])
                e["utilisation"][i] = _num(m["utilisation"])
                if m["limit"] is not None:
                    e["limits"].append(m["limit"])
        out[p] = d
    return out


def _num(x: Any) -> float:
    return float("nan") if x is None else float(x)


def _independent(plan_: StudyPlan, n: int) -> np.ndarray:
    """The rows that are independent draws of the joint distribution (A and B of a
    Saltelli design, every row otherwise)."""
    if plan_.info["method"] == "sobol":
        return saltelli_base_rows(n, len(_names(plan_)))
    return np.arange(n)


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """Percentiles, exceedance probabilities, Sobol' indices and their convergence."""
    done = [v for v in _samples(plan_) if v.name in results]
    if not done:
        return {"title": TITLE, "verdict": {"text": "no sample finished", "ok": None},
                "tables": [], "rows": []}
    probes, conf = settings["probes"], settings["confidence"]
    method = plan_.info["method"]
    out = outputs(plan_, results, probes)
    rows_idx = _independent(plan_, len(_samples(plan_)))
    stats_rows = []
    for p in probes:
        for s, e in out[p].items():
            if s in OUTPUTS:
                continue
            y = e["value"][rows_idx]
            pc = percentiles(y, conf)
            ex = exceedance(e["utilisation"][rows_idx], 1.0, conf)
            lim = sorted(set(e["limits"]))
            stats_rows.append({"probe": p, "standard": s, "metric": e["metric"],
                               "unit": e["unit"], **pc, "exceedance": ex,
                               "limit": lim[0] if len(lim) == 1 else lim,
                               "comparison_only": e["comparison_only"]})
    sobol = _sobol(plan_, out, probes, conf, len(done)) if method == "sobol" else {}
    n_base = len(_samples(plan_)) // (len(_names(plan_)) + 2)
    doubts = {p: {q: d for q, idx in by_q.items() if (d := sobol_doubts(idx, n_base))}
              for p, by_q in sobol.items()}
    shown = {p: {q: idx for q, idx in by_q.items() if q not in doubts[p]}
             for p, by_q in sobol.items()}
    conv = {p: convergence(out[p]["max utilisation"][rows_idx], 1.0, conf) for p in probes}
    tables = _tables(stats_rows, shown, conv, conf, method, len(done), len(_samples(plan_)))
    warnings = []
    if any(doubts.values()):
        tables.insert(2, _doubts_table(doubts, n_base))
        warnings.append(f"Sobol' indices left out of the report for "
                        f"{sum(map(len, doubts.values()))} of {sum(map(len, sobol.values()))} "
                        "outputs: " + next(d for by_q in doubts.values() for d in by_q.values())[0]
                        + f" (the rule: docs/uncertainty.md; at least {MIN_SOBOL_BASE_SAMPLES} "
                        "base points, every index in [0, 1] within its interval)")
    rom = reduced_report(plan_, results, probes) if plan_.info.get("reduced") else None
    if rom is not None:
        tables += rom.pop("tables")
    verdict = _verdict(stats_rows, shown, len(done), conf)
    return {"title": TITLE, "verdict": verdict, "tables": tables, "rows": stats_rows,
            "sobol": sobol, "sobol_doubts": doubts, "sobol_base_points": n_base,
            "warnings": warnings, "convergence": conv, "method": method,
            "bands": _band_percentiles(done, results, probes, rows_idx, plan_),
            "vc_class": plan_.info.get("vc_class"),
            "parameters": _names(plan_), "samples_finished": len(done),
            "design": [[v.parameter[k] for k in _names(plan_)] for v in _samples(plan_)],
            "reduced": rom,
            "outputs": {p: {q: out[p][q] for q in OUTPUTS} for p in probes}}


def _rel(a: float | None, b: float | None) -> float:
    """|a - b| / |b| (NaN when either is missing or b is 0)."""
    if a is None or b is None or not b:
        return float("nan")
    return abs(float(a) - float(b)) / abs(float(b))


def _reference_errors(res: dict, ref: dict, probes: list[str]) -> dict:
    """The reduced sample's errors against its full reference solve."""
    red = ref["model"]["modal"].get("reduced") or {}
    errs: dict[str, float] = {"frequency": max(red.get("frequency_errors") or [np.nan])}
    for p in probes:
        errs[f"{p} peak |a|"] = _rel(res["probes"][p]["acc_total"],
                                     ref["probes"][p]["acc_total"])
        a, b = res["assessment"].get(p) or {}, ref["assessment"].get(p) or {}
        for std, m in (a.get("metrics") or {}).items():
            mb = (b.get("metrics") or {}).get(std)
            if mb is not None:
                errs[f"{p} {std}"] = _rel(m["value"], mb["value"])
    return errs


def reduced_report(plan_: StudyPlan, results: dict[str, dict], probes: list[str]) -> dict:
    """The reduced model's error control: per sample whether its modes were accepted
    (residuals at most the tolerance) or solved in full, and the reference samples'
    errors (frequencies, the probes' peaks and metrics) and times against full solves."""
    info = plan_.info["reduced"]
    used, fallback, worst = [], [], 0.0
    for v in _samples(plan_):
        r = results.get(v.name)
        red = (r or {}).get("model", {}).get("modal", {}).get("reduced") if r else None
        if red is None:
            continue
        (used if red["used"] else fallback).append((v.name, red))
        if red["used"]:
            worst = max(worst, red["max_residual"])
    refs = {}
    for rname, sname in info["references"].items():
        if rname in results and sname in results:
            refs[sname] = {"errors": _reference_errors(results[sname], results[rname], probes),
                           "reduced_used": (results[sname]["model"]["modal"].get("reduced")
                                            or {}).get("used", False),
                           "seconds_reduced": results[sname]["timings"]["modal"],
                           "seconds_full": results[rname]["timings"]["modal"],
                           "total_reduced": results[sname]["timings"]["total"],
                           "total_full": results[rname]["timings"]["total"],
                           "max_residual": results[rname]["model"]["modal"]["reduced"][
                               "max_residual"]}
    t_red = [results[n]["timings"]["total"] for n, _ in used]
    t_full = [e["total_full"] for e in refs.values()]
    speed = (float(np.mean(t_full)) / float(np.mean(t_red))) if t_red and t_full else None
    rows = [["accepted (reduced modes)", str(len(used)), fmt(worst, 3) if used else "–"],
            ["full eigensolve (residual above the tolerance)", str(len(fallback)),
             "; ".join(f"{n}: {red['reason']}" for n, red in fallback[:4])
             + (" ..." if len(fallback) > 4 else "") or "–"]]
    tables = [{"title": "Reduced model: error control", "head": ["samples", "count",
                                                                "max residual / reason"],
               "rows": rows,
               "note": f"Relative residual ||K phi - lambda M phi|| / ||K phi|| of every "
                       f"reduced mode with the sample's own K and M; tolerance "
                       f"uncertainty.reduced_tol = {info['tol']:g}. Seconds per sample: "
                       f"reduced {fmt(float(np.mean(t_red)), 3) if t_red else '–'}, full "
                       f"(reference solves) {fmt(float(np.mean(t_full)), 3) if t_full else '–'}"
                       + (f", speed-up {speed:.2f}" if speed else "") + "."}]
    if refs:
        keys = sorted({k for e in refs.values() for k in e["errors"]})
        tables.append({
            "title": "Reduced model against full solves (reference samples)",
            "head": ["quantity", *refs], "rows": [[k, *(fmt(e["errors"].get(k, np.nan), 2)
                                                      for e in refs.values())] for k in keys],
            "note": "Relative errors of the reduced sample against the same sample solved "
                    "in full on the nominal mesh (frequency: the largest of its modes', by "
                    "index). A reference whose reduced sample fell back to the full "
                    "eigensolve compares full with full."})
    return {"accepted": len(used), "fallback": [{"sample": n, "reason": r["reason"]}
                                                for n, r in fallback],
            "max_residual": worst, "references": refs, "speed_up": speed,
            "seconds_reduced": float(np.mean(t_red)) if t_red else None,
            "seconds_full": float(np.mean(t_full)) if t_full else None, "tables": tables}


def _band_percentiles(done: list, results: dict, probes: list[str], rows_idx: np.ndarray,
                      plan_: StudyPlan) -> dict:
    """P5, P50, P95 of the one-third-octave RMS total acceleration per band [m/s²] over
    the independent finished samples, on the bands every one of them resolves."""
    keep = {_samples(plan_)[i].name for i in rows_idx} & {v.name for v in done}
    out = {}
    for p in probes:
        specs = [results[n]["spectra"].get(p) for n in sorted(keep)]
        specs = [sp for sp in specs if sp and sp.get("bands_hz")]
        if len(specs) < 2:
            continue
        common = sorted(set.intersection(*(set(sp["bands_hz"]) for sp in specs)))
        a = np.array([[dict(zip(sp["bands_hz"], sp["acc_rms"]["total"]))[f] for f in common]
                      for sp in specs])
        pc = np.percentile(a, [5.0, 50.0, 95.0], axis=0)
        out[p] = {"bands_hz": common, "P5": pc[0].tolist(), "P50": pc[1].tolist(),
                  "P95": pc[2].tolist()}
    return out


def _sobol(plan_: StudyPlan, out: dict, probes: list[str], conf: float, n_done: int) -> dict:
    """Sobol' indices per probe and output (only with the whole Saltelli design)."""
    if n_done < len(_samples(plan_)):
        return {}
    names = _names(plan_)
    res = {}
    for p in probes:
        res[p] = {}
        for q in OUTPUTS:
            y = out[p][q]
            if np.isfinite(y).all() and np.ptp(y) > 0:
                res[p][q] = sobol_indices(names, y, conf)
    return res


def _doubts_table(doubts: dict, n_base: int) -> dict:
    """The outputs whose Sobol' indices are left out, and why (:func:`sobol_doubts`)."""
    rows = [[p, q, "; ".join(d)] for p, by_q in doubts.items() for q, d in by_q.items()]
    return {"title": "Sobol' indices left out",
            "head": ["probe", "output", "why"], "rows": rows,
            "note": f"Not estimates: the indices of a Saltelli design are shown only with at "
                    f"least {MIN_SOBOL_BASE_SAMPLES} base points (this design: {n_base}) and "
                    "when every index lies in [0, 1] within its bootstrap interval (Saltelli "
                    "et al. 2010 use 10^2 to 10^4 base points; docs/uncertainty.md). Run "
                    "more base points (uncertainty.samples, a power of 2); the raw numbers "
                    "stay in report.json (analysis.sobol) for inspection, not for decisions."}


def _interval(e: dict, digits: int = 3) -> str:
    return f"{fmt(e['value'], digits)} [{fmt(e['low'], digits)}, {fmt(e['high'], digits)}]"


def _tables(stats_rows, sobol, conv, conf, method, n_done, n_all) -> list[dict]:
    c = f"{100 * conf:g} %"
    tables = [{
        "title": "Percentiles of each metric",
        "head": ["probe", "standard", "metric", "unit", "P5", "P50", "P95", "limit"],
        "rows": [[r["probe"], r["standard"], r["metric"], r["unit"], _interval(r["P5"]),
                  _interval(r["P50"]), _interval(r["P95"]),
                  fmt(r["limit"]) if not isinstance(r["limit"], list) else
                  "varies" if r["limit"] else "–"] for r in stats_rows],
        "note": f"Governing direction of each standard; [{c} percentile-bootstrap interval]. "
                f"{n_done} of {n_all} samples finished (method {method}"
                + ("; percentiles from the A and B rows of the Saltelli design" if
                   method == "sobol" else "") + "). limit 'varies': the governing "
                "limit differs between samples (a frequency-dependent limit, e.g. DIN "
                "4150-3's PPV line or a VC curve, at each sample's dominant frequency); "
                "the exceedance uses each sample's own utilisation."},
        {"title": "Probability of exceeding each limit",
         "head": ["probe", "standard", "P(utilisation > 1)", f"{c} Wilson interval",
                  "exceeding / samples"],
         "rows": [[r["probe"], r["standard"] + (" (comparison only)" if r["comparison_only"]
                                                else ""),
                   pct(r["exceedance"]["p"], 1),
                   f"[{pct(r['exceedance']['low'], 1)}, {pct(r['exceedance']['high'], 1)}]",
                   f"{r['exceedance']['k']} / {r['exceedance']['n']}"] for r in stats_rows]}]
    for p, by_q in sobol.items():
        for q, idx in by_q.items():
            ranked = sorted(idx, key=lambda k: -idx[k]["ST"])
            tables.append({"title": f"Sobol' indices of {p} {q}",
                           "head": ["rank", "parameter", "S1", "ST"],
                           "rows": [[str(k + 1), n, f"{idx[n]['S1']:.3f} ± "
                                     f"{idx[n]['S1_conf']:.3f}", f"{idx[n]['ST']:.3f} ± "
                                     f"{idx[n]['ST_conf']:.3f}"] for k, n in enumerate(ranked)],
                           "note": f"First-order and total indices (SALib), ± half the {c} "
                                   "bootstrap interval; ranked by the total index."})
    rows = [[p, str(e["n"]), _interval(e["P50"]), _interval(e["P95"]),
             "–" if e["exceedance"] is None else
             f"{pct(e['exceedance']['p'], 1)} [{pct(e['exceedance']['low'], 1)}, "
             f"{pct(e['exceedance']['high'], 1)}]"] for p, es in conv.items() for e in es]
    tables.append({"title": "Convergence with the sample count (largest utilisation)",
                   "head": ["probe", "samples", "P50", "P95", "P(> 1)"], "rows": rows,
                   "note": "The estimates from the first n samples: enough samples are in "
                           "when the intervals are as narrow as the decision needs."})
    return tables


def _verdict(stats_rows: list[dict], sobol: dict, n_done: int, conf: float) -> dict:
    binding = [r for r in stats_rows if not r["comparison_only"]
               and r["exceedance"]["n"] > 0]
    if not binding:
        return {"text": f"{n_done} samples; no binding standard was assessed", "ok": None}
    worst = max(binding, key=lambda r: (r["exceedance"]["p"], r["P95"]["value"]
                                        if math.isfinite(r["P95"]["value"]) else 0.0))
    ex = worst["exceedance"]
    text = (f"{n_done} samples: largest probability of exceeding a limit "
            f"{pct(ex['p'], 1)} ({100 * conf:g} % interval {pct(ex['low'], 1)}–"
            f"{pct(ex['high'], 1)}) at {worst['probe']}, {worst['standard']} "
            f"(P95 of {worst['metric']} = {fmt(worst['P95']['value'], 3)} {worst['unit']})")
    drivers = {}
    for p, by_q in sobol.items():
        idx = by_q.get("peak |a|")
        if idx:
            drivers[p] = max(idx, key=lambda k: idx[k]["ST"])
    if drivers:
        text += "; driven by " + ", ".join(f"{n} ({p})" for p, n in drivers.items())
    return {"text": text, "ok": ex["high"] < 0.05 if ex["n"] else None,
            "max_exceedance": ex, "governing": [worst["probe"], worst["standard"]],
            "drivers": drivers}


def progress(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> str:
    """One line of the statistics of the finished samples (printed after each sample)."""
    n = sum(v.name in results for v in _samples(plan_))
    if n < 2:
        return f"[uncertainty] {n} of {len(_samples(plan_))} samples finished"
    out = outputs(plan_, results, settings["probes"])
    conf = settings["confidence"]
    parts = []
    for p in settings["probes"]:
        u = out[p]["max utilisation"]
        if not np.isfinite(u).any():
            continue
        p95 = percentiles(u, conf, q=(95.0,))["P95"]
        ex = exceedance(u, 1.0, conf)
        parts.append(f"{p}: P95 utilisation {_interval(p95)}, P(>1) {pct(ex['p'], 1)} "
                     f"[{pct(ex['low'], 1)}, {pct(ex['high'], 1)}]")
    return (f"[uncertainty] {n} of {len(_samples(plan_))} samples: "
            + ("; ".join(parts) or "no utilisation assessed"))


def write_results(analysis: dict, root: Path) -> dict[str, Path]:
    """``uncertainty.h5``: the design and the outputs per sample (rank 0)."""
    import h5py

    from ..io.atomic import atomic_file
    from ..io.files import UNCERTAINTY_H5

    if "design" not in analysis:
        return {}
    path = root / UNCERTAINTY_H5
    with atomic_file(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["method"] = analysis["method"]
        f.attrs["parameters"] = list(analysis["parameters"])
        f.create_dataset("design", data=np.asarray(analysis["design"], dtype=float))
        for p, by_q in analysis["outputs"].items():
            g = f.create_group(p)
            for q, y in by_q.items():
                g.create_dataset(q.replace("|a|", "abs_a").replace(" ", "_"), data=y)
    return {"hdf5": path}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """The convergence of P95 and of the exceedance probability per probe, and the
    one-third-octave percentile bands against the VC curve."""
    conv = analysis.get("convergence") or {}
    if not conv:
        return []
    return [_convergence_figure(conv, fig_dir),
            *([_bands_figure(analysis["bands"], analysis.get("vc_class"), fig_dir)]
              if analysis.get("bands") else [])]


def _bands_figure(bands: dict, vc_class: str | None, fig_dir: Path) -> Path:
    """P5-P95 of the band spectra per probe, the median, and the building's VC curve as an
    acceleration at the band centres (2 pi f v_VC)."""
    from ..assess.standards import vc_curve

    probes = list(bands)[:4]
    fig = figure(figsize=(11, 7))
    axes = np.atleast_1d(fig.subplots(2, 2)).ravel()
    for ax, p in zip(axes, probes):
        b = bands[p]
        f = np.asarray(b["bands_hz"])
        ax.fill_between(f, b["P5"], b["P95"], alpha=0.3, label="P5–P95")
        ax.loglog(f, b["P50"], "o-", ms=3, label="P50")
        if vc_class:
            ax.loglog(f, 2 * np.pi * f * vc_curve(f, vc_class), "k--", lw=1,
                      label=f"VC {vc_class} (as 2πf v)")
        ax.set_title(p)
        ax.set_xlabel("one-third-octave band [Hz]")
        ax.set_ylabel("RMS acceleration [m/s²]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    for ax in axes[len(probes):]:
        ax.set_visible(False)
    return save(fig, fig_dir / "uncertainty_bands.png")


def _convergence_figure(conv: dict, fig_dir: Path) -> Path:
    fig = figure(figsize=(11, 4.2))
    a1, a2 = fig.subplots(1, 2)
    for p, es in conv.items():
        n = [e["n"] for e in es]
        a1.errorbar(n, [e["P95"]["value"] for e in es], fmt="o-", ms=3, label=p,
                    yerr=np.abs(np.array([[e["P95"]["value"] - e["P95"]["low"],
                                           e["P95"]["high"] - e["P95"]["value"]]
                                          for e in es]).T))
        a2.plot(n, [e["exceedance"]["p"] for e in es], "o-", ms=3, label=p)
        a2.fill_between(n, [e["exceedance"]["low"] for e in es],
                        [e["exceedance"]["high"] for e in es], alpha=0.15)
    a1.set_ylabel("P95 of the largest utilisation")
    a2.set_ylabel("P(utilisation > 1)")
    for ax in (a1, a2):
        ax.set_xscale("log")
        ax.set_xlabel("samples")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    return save(fig, fig_dir / "uncertainty_convergence.png")


STUDY = Study(
    name="uncertainty",
    help="uncertainty: the case's uncertain inputs sampled, statistics and sensitivities",
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    needs_track=("its samples and reduced model are built for the train's passage (not "
                 "yet for the moving load of [load])"),
    prepare=prepare, progress=progress, listing_columns=listing_columns,
    write_results=write_results,
)
