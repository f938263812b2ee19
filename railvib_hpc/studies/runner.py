"""``railvib study KIND CASE``: run the variants of a study, then merge them into a report.

Modes of the command (see ``jobs/README.md``):

* default: compute every variant that is not finished (shared model first), then merge;
* ``--variant NAME|INDEX`` (repeatable): compute only these (e.g. one SLURM/PBS array task
  each; the index is 0-based in ``--list`` order), no report;
* ``--prepare``: only the shared model of the ``modes``/``speed`` studies (run it once
  before an array of variants, so the tasks do not all compute it);
* ``--merge``: no computation, the report from the finished variants;
* ``--list``: the variants, their overrides and status.

Every variant's result is a ``result.json`` written atomically at its end: an interrupted
study resumes where it stopped (finished variants are skipped, the stages reuse their
files). :func:`execute_study` returns a summary (the variants and their status, the
failed ones, the verdict, tables and report files); the command line exits with code 2
when a selected variant failed with a user error (e.g. the modal stage's memory check).
The report is written either way.

The studies are those of the registry (:mod:`.registry`, each module's ``STUDY``, a
:class:`~.protocol.Study`): this runner knows no study by name, it calls what a study
declares (its plan, its variants' computation, its analysis, figures and hooks).
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..config import Case
from ..errors import CaseError
from ..io.locks import output_lock
from ..log import Reporter
from ..parallel import on_root
from .common import (
    FAILED_NAME,
    SHARED_DIR,
    StudyError,
    StudyPlan,
    band_coverage,
    prepare_shared,
    read_failure,
    read_result,
    resolved_spectra,
    run_variant,
    surface_load_info,
    variant_case,
    variant_digest,
)
from .registry import STUDIES, STUDY_MODULES, study
from .report import fmt, text_table, write_report
from .settings import StudySettingsError, study_settings

if TYPE_CHECKING:
    from mpi4py import MPI

__all__ = ["STUDY_MODULES", "execute_study", "make_plan", "merge", "select", "status",
           "trackless_kinds", "trackless_problem"]


def trackless_kinds() -> tuple[str, ...]:
    """The studies that run a case without a track (``track.count = 0``: the moving load of
    ``[load]`` on the bare soil) with ``solver = direct``: those that declare no need of a
    track (``Study.needs_track``; their variants change the mesh, the domain, the soil or
    the building, or the load's speed). The others compare the vehicle on the track's
    modes (``modes``, ``thesis``) or sample the train's inputs (``uncertainty``, not yet
    without a track); in alphabetical order."""
    return tuple(sorted(name for name in STUDIES if study(name).needs_track is None))


def trackless_problem(kind: str, case: Case, settings: dict[str, Any]
                      ) -> tuple[str, Any, str] | None:
    """What a study cannot do with a case without a track (None: it can, or the case has
    a track): a study of :func:`trackless_kinds` with ``solver = direct`` (the transient
    engines), and what the study's own ``trackless_problem`` finds in its settings (e.g. a
    mitigation measure on the track's keys).

    Returns
    -------
    tuple or None
        One ``(key, value, allowed)`` problem, for :class:`~railvib_hpc.errors.CaseError`.
    """
    if case["track.count"] != 0:
        return None
    declared = study(kind)
    if declared.needs_track is not None:
        return ("track.count", 0, f"railvib study {kind} needs a track (1 or 2): "
                f"{declared.needs_track}; a case without a track runs the studies "
                f"{', '.join(trackless_kinds())} with solver = direct")
    if settings.get("solver") != "direct":
        return (f"study.{kind}.solver", settings.get("solver"),
                "a case without a track (track.count = 0: the moving load of [load]) runs "
                "its studies on the full-order transient engines only: set it to direct "
                f"(--study-set solver=direct, or solver = \"direct\" in [study.{kind}])")
    own = declared.trackless_problem
    return own(settings) if own is not None else None


def _refuse_trackless(kind: str, case: Case, settings: dict[str, Any]) -> None:
    """Raise the :func:`trackless_problem` of a study, if any (before anything is written).

    Raises
    ------
    CaseError
        One line naming the key, its value and what is allowed.
    """
    problem = trackless_problem(kind, case, settings)
    if problem is not None:
        raise CaseError([problem])


def make_plan(kind: str, case: Case, settings: dict[str, Any], root: Path | None = None
              ) -> StudyPlan:
    """The study's variants; every variant case is validated (rank 0). ``root``: the
    study's folder (for a study whose variants name files in it, ``PLAN_IN_FOLDER``)."""
    from ..mesh.layout import build_layout

    known = list(build_layout(case).probes)
    bad = [p for p in settings.get("probes", ()) if p not in known]
    if bad:
        raise StudySettingsError(kind, [(f"study.{kind}.probes", settings["probes"],
                                         f"unknown probes {bad}; the mesh has: "
                                         + ", ".join(known))])
    plan = study(kind).plan(case, settings, root=root)
    for v in plan.variants:
        variant_case(case, v.overrides)
    if plan.shared_overrides is not None:
        variant_case(case, plan.shared_overrides)
    return plan


def select(plan: StudyPlan, wanted: Sequence[str]) -> list:
    """Variants named (or 0-based indices) in ``wanted``.

    Raises
    ------
    StudyError
        Naming the unknown entry and the allowed names.
    """
    names = [v.name for v in plan.variants]
    out = []
    for w in wanted:
        for part in str(w).split(","):
            part = part.strip()
            if not part:
                continue
            if part.isdigit() and part not in names:
                k = int(part)
                if k >= len(names):
                    raise StudyError(f"--variant {part}: index out of range; the "
                                     f"{plan.kind} study has variants 0..{len(names) - 1} "
                                     f"({', '.join(names)})")
                part = names[k]
            if part not in names:
                raise StudyError(f"--variant {part!r}: unknown variant of the {plan.kind} "
                                 f"study; allowed: {', '.join(names)} (or 0..{len(names) - 1})")
            v = plan.variants[names.index(part)]
            if v not in out:
                out.append(v)
    return out


def status(plan: StudyPlan, case: Case, root: Path, settings: dict) -> tuple[list, dict]:
    """Status of every variant and the finished results (rank 0)."""
    entries, results = [], {}
    for v in plan.variants:
        vdir = root / v.name
        digest = variant_digest(plan.kind, variant_case(case, v.overrides), settings)
        res = read_result(vdir, digest)
        entry = {"name": v.name, "parameter": v.parameter, "overrides": list(v.overrides),
                 "folder": str(vdir)}
        if res is not None:
            results[v.name] = res
            entry.update(status="finished", wall_s=res["timings"]["total"],
                         ranks=res.get("ranks"))
        elif read_result(vdir) is not None:
            entry.update(status="stale", error="result of other inputs (case changed)")
        else:
            fail = read_failure(vdir)
            if fail is not None and fail.get("inputs_sha256") == digest:
                entry.update(status="failed", error=fail.get("error"))
            else:
                entry["status"] = "pending"
        entries.append(entry)
    return entries, results


def merge(kind: str, plan: StudyPlan, case: Case, root: Path, settings: dict,
          rep: Reporter, merge_only: bool = False) -> dict:
    """Analyse the finished variants and write the report (rank 0).

    The analysis sees each variant's spectra cut to the bands its solution resolves
    (:func:`~.common.resolved_spectra`); the report adds the band of every variant, a
    warning when one ends below the assessment band, and says how many variants are not
    finished (the verdict then covers the finished ones only).

    Raises
    ------
    StudyError
        With ``merge_only`` (``--merge``) when no variant has finished: there is nothing
        to report.
    """
    declared = study(kind)
    entries, results = status(plan, case, root, settings)
    if merge_only and not results:
        counts: dict[str, int] = {}
        for e in entries:
            counts[e["status"]] = counts.get(e["status"], 0) + 1
        raise StudyError(
            f"study {kind} --merge: none of the {len(entries)} variants has finished ("
            + ", ".join(f"{n} {st}" for st, n in counts.items()) + f") in {root}: compute "
            f"them first (railvib study {kind} CASE --out ..., without --merge)")
    coverage = band_coverage(plan, results)
    shown = {name: resolved_spectra(r) for name, r in results.items()}
    analysis = _annotate({"title": declared.title, **declared.analyse(plan, shown, settings)},
                         entries, coverage)
    if coverage["warning"]:
        rep.info(f"WARNING: {coverage['warning']}")
    for warning in analysis.get("warnings", []):        # e.g. Sobol' indices left out
        rep.info(f"WARNING: {warning}")
    results = shown
    figs = declared.figures(analysis, settings, root / "figures", results=results)
    files = write_report(root, kind, case_info(case), settings, entries, analysis, figs)
    if declared.write_results is not None:            # e.g. the uncertainty study's HDF5
        files.update(declared.write_results(analysis, root))
    for t in analysis.get("tables", []):
        if t["rows"]:
            rep.info(f"{t['title']}:\n" + text_table(t["head"], t["rows"]))
    rep.info(f"{kind} study: {sum(e['status'] == 'finished' for e in entries)} of "
             f"{len(entries)} variants finished")
    rep.info(f"VERDICT: {analysis['verdict']['text']}")
    rep.info(f"wrote {files['markdown']}, {files['json']}"
             + "".join(f", {p}" for p in figs))
    return {"verdict": analysis["verdict"], "files": {k: str(p) for k, p in files.items()},
            "variants": entries, "tables": analysis.get("tables", []),
            "rows": analysis.get("rows", []), "figures": [str(p) for p in figs]}


def case_info(case: Case) -> dict[str, str]:
    """The case as the report names it: ``name``, ``file``, and for a case without a track
    ``loading``, the sentence that says the moving load of ``[load]`` loads it and that the
    vehicle's quantities are absent."""
    info = {"name": case["case.name"], "file": str(case.path or "<defaults>")}
    if case["track.count"] == 0:
        ld = surface_load_info(case)
        info["loading"] = (
            f"no track (track.count = 0): the moving load of [load] on the bare soil, "
            f"{ld['count']} load(s) of {ld['force']:g} N at {ld['speed']:g} m/s "
            f"along y = {ld['y']:g} m (the variants' own values where they change them); "
            "no vehicle: the contact forces, wheel loads and rail deflection are absent from "
            "this report (result.json: mbs = null, load = the moving load)")
    return info


def _solver_text(variant: dict) -> str:
    """``modal``, or ``direct`` with the time-domain engine that ran it (``direct/imex``)."""
    engine = variant.get("engine")
    if variant["solver"] != "direct" or engine in (None, "direct"):
        return variant["solver"]
    return f"direct/{engine}"


def _annotate(analysis: dict, entries: list[dict], coverage: dict) -> dict:
    """The analysis with what every study's report says: the unfinished variants (in the
    verdict), the band of each finished variant (a table) and the band warning."""
    analysis = dict(analysis)
    verdict = dict(analysis["verdict"])
    missing = [e for e in entries if e["status"] != "finished"]
    finished = len(entries) - len(missing)
    verdict["complete"] = not missing
    verdict["missing"] = [e["name"] for e in missing]
    if missing:
        shown = ", ".join(f"{e['name']} {e['status']}" for e in missing[:8]) \
            + (", ..." if len(missing) > 8 else "")
        verdict["text"] = (f"INCOMPLETE: {len(missing)} of {len(entries)} variants not "
                           f"finished ({shown}); from the {finished} finished only: "
                           + verdict["text"])
    verdict["band_warning"] = coverage["warning"]
    if coverage["warning"]:
        verdict["text"] += f" [WARNING: {coverage['warning']}]"
    analysis["verdict"] = verdict
    analysis["band_coverage"] = coverage
    if coverage["variants"]:
        lo, hi = coverage["assessment_band_hz"]
        rows = [[p["variant"], _solver_text(p), fmt(p["modes"]), fmt(p["f1_hz"]),
                 fmt(p["f_max_hz"]), fmt(p["top_band_hz"])] for p in coverage["variants"]]
        analysis["tables"] = [*analysis.get("tables", []), {
            "title": "Frequency band of each variant",
            "head": ["variant", "solver", "modes", "f1 [Hz]", "resolved up to [Hz]",
                     "highest band reported [Hz]"], "rows": rows,
            "note": f"The assessment band is {lo:g}–{hi:g} Hz. resolved up to: the highest "
                    "mode used (modal) or transient.f_max (direct; direct/explicit and "
                    "direct/imex: the full model by that transient.engine). "
                    "One-third-octave bands "
                    "above it are not reported; peaks and assessments miss the response "
                    "above it." + (f" WARNING: {coverage['warning']}."
                                   if coverage["warning"] else "")}]
    return analysis


def listing(kind: str, plan: StudyPlan, case: Case, root: Path, settings: dict) -> str:
    """What ``--list`` prints: the folder, then one row per variant (its index, name, what
    sets it apart, status).

    The overrides every variant shares are printed once above the table, each row shows
    only its own; a study module with a ``listing_columns(plan, case, entries)`` hook
    shows columns of its own instead (the uncertainty study: one column per sampled
    parameter).
    """
    entries, _ = status(plan, case, root, settings)
    lines = [f"{kind} study, folder {root}" + (f" (shared model in {root / SHARED_DIR})"
                                               if plan.shared_overrides is not None else "")]
    hook = study(kind).listing_columns
    if hook is not None:
        notes, head, cells = hook(plan, case, entries)
        lines += notes
        rows = [[str(i), e["name"], *c, e["status"]] for i, (e, c) in
                enumerate(zip(entries, cells))]
        return "\n".join([*lines, text_table(["index", "variant", *head, "status"], rows)])
    shared = [o for o in entries[0]["overrides"]
              if all(o in e["overrides"] for e in entries)] if len(entries) > 1 else []
    if shared:
        lines.append("every variant: " + " ".join(shared))
    rows = [[str(i), e["name"], " ".join(o for o in e["overrides"] if o not in shared),
             e["status"]] for i, e in enumerate(entries)]
    return "\n".join([*lines, text_table(["index", "variant", "overrides", "status"], rows)])


def execute_study(kind: str, case: Case, out: Path, comm: MPI.Comm, rep: Reporter, *,
                  variants: Sequence[str] = (), merge_only: bool = False,
                  prepare: bool = False, list_only: bool = False,
                  study_set: Sequence[str] = (), settings: dict[str, Any] | None = None,
                  petsc_options: Sequence[str] | None = None, wait: bool = False) -> dict:
    """Run a study (collective); returns its summary (the same on every rank).

    The public entry point is :func:`railvib_hpc.api.run_study`, which wraps this
    summary into a :class:`~railvib_hpc.api.StudyResult`.

    Parameters
    ----------
    kind
        A registered study (:data:`~.registry.STUDIES`).
    case
        The validated case (broadcast to every rank).
    out
        Output folder; the study writes into ``out/<kind>/``.
    comm
        MPI communicator.
    rep
        Reporter (rank 0 prints).
    variants
        Names or 0-based indices of the variants to compute (empty: all); with names given
        no report is written.
    merge_only
        Only write the report from the finished variants.
    prepare
        Only compute the shared model (``modes`` and ``speed`` studies).
    list_only
        Only print the variants and their status.
    study_set
        ``key=value`` study settings (``--study-set``).
    settings
        Study settings given programmatically (merged before ``study_set``).
    petsc_options
        PETSc/SLEPc options (after ``--``), passed to PETSc when a model is computed
        (the list is not changed).
    wait
        Wait for another command that holds a variant folder (``--wait``) instead of
        failing that variant.

    Returns
    -------
    dict
        ``kind``, ``folder``, ``settings`` (validated), ``variants`` (name, parameter,
        overrides, folder, status, error), ``computed`` and ``failed`` (variant names of
        this call), ``merged`` (whether the report was written), ``verdict``, ``tables``,
        ``files`` and ``figures`` (of the report; empty when not merged), ``seconds``.
    """
    t0 = time.perf_counter()
    cfg = on_root(lambda: study_settings(kind, study_set, settings, case), comm)
    on_root(lambda: _refuse_trackless(kind, case, cfg), comm)
    root = Path(out) / kind
    plan = on_root(lambda: make_plan(kind, case, cfg, root), comm)
    chosen = on_root(lambda: select(plan, variants), comm) if variants else []
    if list_only:
        on_root(lambda: rep.info(listing(kind, plan, case, root, cfg)), comm)
        return _summary(kind, plan, case, root, cfg, comm, t0, [], [], None)
    failed: list[str] = []
    computed: list[str] = []
    if not merge_only:
        from ..petsc_env import init_petsc

        init_petsc(list(petsc_options or []))
        todo = chosen or ([] if prepare else list(plan.variants))
        if prepare and plan.shared_overrides is None:
            rep.info(f"the {kind} study has no shared model: every variant builds its own "
                     "(nothing to prepare)")
        elif prepare or any(v.shared for v in todo):
            prepare_shared(plan, case, root, comm, rep)
        declared = study(kind)
        hook = declared.prepare
        if hook is not None and (todo or prepare):   # the uncertainty study's reduced model
            hook(plan, case, root, comm, rep)
        progress = declared.progress
        # the finished results, kept up to date for the statistics printed after each one
        known = on_root(lambda: status(plan, case, root, cfg)[1], comm) if progress else {}
        for v in todo:
            with rep.stage(f"{kind}/{v.name}"):
                res = run_variant(plan, v, case, root, comm, rep, cfg, wait=wait,
                                  compute=declared.variant)
            if "failed" in res:
                failed.append(v.name)
            else:
                computed.append(v.name)
                known[v.name] = res
            if progress is not None:
                on_root(lambda: rep.info(progress(plan, known, cfg)), comm)
    merged = None
    if merge_only or not (chosen or prepare):
        with output_lock(root, comm, f"study {kind} --merge", wait=True, rep=rep):
            merged = on_root(lambda: merge(kind, plan, case, root, cfg, rep,
                                           merge_only=merge_only), comm)
    rep.info(f"{kind} study command finished in {time.perf_counter() - t0:.1f} s"
             + (f"; failed variants: {', '.join(failed)} (see their {FAILED_NAME})"
                if failed else ""))
    return _summary(kind, plan, case, root, cfg, comm, t0, computed, failed, merged)


def _summary(kind: str, plan: StudyPlan, case: Case, root: Path, cfg: dict, comm, t0: float,
             computed: list[str], failed: list[str], merged: dict | None) -> dict:
    """The summary :func:`execute_study` returns (every rank)."""
    entries = merged["variants"] if merged is not None else \
        on_root(lambda: status(plan, case, root, cfg)[0], comm)
    merged = merged or {}
    return {"kind": kind, "folder": str(root), "settings": cfg, "variants": entries,
            "computed": computed, "failed": failed, "merged": bool(merged),
            "verdict": merged.get("verdict"), "tables": merged.get("tables", []),
            "rows": merged.get("rows", []),
            "files": merged.get("files", {}), "figures": merged.get("figures", []),
            "seconds": time.perf_counter() - t0}
