"""What every study shares: variants, their folders and result files, and the responses.

Folders (``<out>`` is the ``--out`` folder of the command)::

    <out>/<study>/<variant>/          one folder per variant
        mesh.h5, modes.h5, ...        own model (convergence, reflection), or
        modes.h5 -> ../model/modes.h5 links to the shared model (modes, speed studies)
        mbs.h5, mbs_*.png             the multibody run of the variant
        probes.h5                     probe histories (from the modes, see below)
        result.json                   the variant's result, written last and atomically
        failed.json                   written instead when the variant failed (user error)
        run.json                      its modal and mbs stage calls (times, memory, versions)
    <out>/<study>/model/              shared model of the modes and speed studies

Building responses come from :func:`railvib_hpc.reconstruct.probes.probe_histories`: the
mode shapes interpolated at the probe points times the modal histories of ``mbs.h5`` (plus
the static-correction basis when it is on, for displacements only unless
``output.static_correction_rates``). That is exactly what the reconstruct stage
writes to ``probes.h5`` for these points, without the full fields (GBs per variant).

``result.json`` (schema ``railvib_hpc.study/1``, a stage file of
:mod:`railvib_hpc.io.products`)::

    study, variant, parameter {..}, overrides [..], inputs_sha256, provenance {..},
    complete = true,
    model   {n_nodes, n_hexes, n_dofs, modes_in_file, modes_used, frequencies_hz [..],
             f_max_hz, modal {factor_memory_gb, time_factorization, time_solve,
             peak_rss_gb_total, ranks, ...}}
    mbs     {peak_contact_force, static_wheel_load, dynamic_increment, dynamic_factor,
             min_contact_force, max_rail_deflection, dt, n_steps, loss_of_contact_steps}
            (null for a case without a track, track.count = 0: no vehicle)
    load    {type = "surface_load", force, count, speed, y}   (only without a track: the
            moving load of [load] that replaces the vehicle)
    probes  {name: {coords, t_onset, acc_x, acc_y, acc_vertical, acc_total, t_acc_total,
                    vel_total, disp_total}}                      (every mesh probe; t_onset:
                    first time |a| reaches assessment.wave_threshold of its peak)
    assessment {name: {passed, max_utilisation, utilisation {standard: value}}}
    spectra {name: {bands_hz, acc_rms {x, y, z, total}}}    (one-third octaves, 1-80 Hz)
    timings {modal, mbs, response, total} [s], reused {modes, mbs}

A variant is *finished* when its ``result.json`` is complete, its ``inputs_sha256``
(the full variant case, the study and the result format) matches, the files it was
computed from (``modes.h5``, ``mbs.h5``, ``probes.h5`` in the variant folder, where they
still exist) are the ones it recorded, and its content is unchanged: reruns skip it.

Locks: each variant folder is locked while its variant runs (array jobs on different
variants run concurrently), the shared model folder while it is computed (other tasks
wait for it), and the study folder while the report is merged.
"""

from __future__ import annotations

import json
import math
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import __version__
from ..config import Case, build_case, parse_override
from ..errors import UserError
from ..io.atomic import copy_file, write_json, write_text
from ..io.digests import digest, file_digest
from ..io.files import (
    FAILED_JSON,
    MBS_H5,
    MODAL_DAMPING_H5,
    MODES_H5,
    PROBES_H5,
    RESULT_JSON,
    STATIC_H5,
    TRANSIENT_H5,
)
from ..io.products import ALL_KEYS, StageFile, declare
from ..io.provenance import examine, provenance
from ..io.stage_protocol import StageRunner
from ..log import Reporter
from ..parallel import on_root
from ..pipeline import run_stage
from ..validation import switched_off

if TYPE_CHECKING:
    from mpi4py import MPI

#: The assessment band [Hz]: the one-third-octave bands of the criteria (VC curves, the
#: ISO 2631 / DIN 4150-2 weightings) and the spectra of the studies.
ASSESSMENT_BAND_HZ = (1.0, 80.0)

#: Bumped when the content of ``result.json`` changes (part of the variant digest).
RESULT_FORMAT = "railvib_hpc.study/1"
RESULT_NAME = RESULT_JSON
#: ``result.json`` of a variant: the whole variant case (and the study's settings, in the
#: digest the study gives it), computed from the modal solution's files or the full-order
#: solution's (``transient.h5``).
RESULT_FILE = declare(StageFile(RESULT_JSON, "study", 2, ALL_KEYS,
                                (MODES_H5, STATIC_H5, MBS_H5, PROBES_H5, TRANSIENT_H5), (),
                                ("mesh.file", "irregularity.file")))
FAILED_NAME = FAILED_JSON
SHARED_DIR = "model"
#: Files of the shared model linked into each variant folder.
SHARED_FILES = (MODES_H5, STATIC_H5, MODAL_DAMPING_H5)


class StudyError(UserError):
    """A study that cannot run (unknown variant, missing shared model, missing probe...)."""


@dataclass(frozen=True)
class Variant:
    """One run of a study.

    Attributes
    ----------
    name
        Folder name (unique in the study).
    overrides
        Case overrides (``key=value``, TOML values) applied to the study's case.
    parameter
        What distinguishes it, for tables (e.g. ``{"refinement": 0.5}``).
    shared
        True when the variant reuses the study's shared model (only MBS + probes run).
    band_hz
        > 0: the MBS uses exactly the modes below this frequency; the modal solve asks for
        ``modal.n_modes`` modes and is repeated with more (scaled by Weyl's law,
        N ~ f^3) while the highest mode is below the band.
    """

    name: str
    overrides: tuple[str, ...]
    parameter: dict[str, Any] = field(default_factory=dict)
    shared: bool = False
    band_hz: float = 0.0


@dataclass(frozen=True)
class StudyPlan:
    """The variants of a study and, if any, the overrides of its shared model."""

    kind: str
    variants: tuple[Variant, ...]
    shared_overrides: tuple[str, ...] | None = None
    #: What the study's analysis needs to know of the plan (e.g. the uncertainty study's
    #: sampling method and parameter names).
    info: dict[str, Any] = field(default_factory=dict)


def variant_case(case: Case, overrides: Sequence[str]) -> Case:
    """The study's case with a variant's overrides (validated like ``--set``).

    A variant that switches a feature of the case off (the reflection study's rollers in
    place of the case's pml faces) resets the keys of that feature to their defaults
    (:func:`~railvib_hpc.validation.switched_off`): they no longer apply, and the case
    rule refuses them where they do not (:func:`~railvib_hpc.validation.feature_key_problems`).
    """
    data = json.loads(json.dumps(case.data))
    changes = {}
    for text in overrides:
        key, value = parse_override(text)
        changes[key] = value
    for key, default in switched_off(case, changes).items():
        node = data
        *sections, leaf = key.split(".")
        for part in sections:
            node = node[part]
        node[leaf] = default
    return build_case(data, list(overrides), case.path)


def variant_digest(kind: str, vcase: Case, settings: dict[str, Any]) -> str:
    """SHA-256 identifying a variant's result: its full case, the study, the format."""
    payload = {"format": RESULT_FORMAT, "version": __version__, "study": kind,
               "case": vcase.digest(), "probes": settings.get("probes")}
    if settings.get("solver", "modal") != "modal":
        payload["solver"] = settings["solver"]
    return digest(payload)


def jsonable(x: Any) -> Any:
    """Numpy values to plain Python, non-finite floats to None (strict JSON)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist())
    if isinstance(x, np.generic):
        x = x.item()
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def read_result(vdir: Path, digest: str | None = None) -> dict | None:
    """The complete ``result.json`` of a variant (None if missing, incomplete, stale or
    corrupt; with ``digest`` also None for another variant case or other upstream files)."""
    path = vdir / RESULT_NAME
    verdict = examine(path, RESULT_NAME, inputs_sha256=digest, companions=False)
    if not verdict.ok and not (digest is None and verdict.kind == "inputs"):
        return None
    try:
        res = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if res.get("complete") is not True or res.get("schema") != RESULT_FORMAT:
        return None
    if digest is not None and res.get("inputs_sha256") != digest:
        return None
    return res


def read_failure(vdir: Path) -> dict | None:
    """The ``failed.json`` of a variant, if any."""
    try:
        return json.loads((vdir / FAILED_NAME).read_text())
    except (OSError, ValueError):
        return None


def write_result(vdir: Path, result: dict, vcase: Case | None = None) -> None:
    """Write ``result.json`` atomically with its provenance (the digests of the variant's
    ``modes.h5``, ``static.h5``, ``mbs.h5`` and ``probes.h5``, or of the full-order
    solution's ``transient.h5`` and ``probes.h5``) and drop an old ``failed.json``."""
    upstream = {n: file_digest(vdir / n).sha256 for n in (MODES_H5, STATIC_H5, MBS_H5,
                                                          TRANSIENT_H5, PROBES_H5)
                if (vdir / n).exists()}
    prov = provenance(RESULT_NAME, vcase, upstream, inputs_sha256=result.get("inputs_sha256"))
    write_json(vdir / RESULT_NAME, jsonable(result), prov)
    (vdir / FAILED_NAME).unlink(missing_ok=True)


def link_shared(shared: Path, vdir: Path) -> list[str]:
    """Link the shared model's files into a variant folder (relative symlinks; copies if
    the file system has none). Returns the names linked."""
    vdir.mkdir(parents=True, exist_ok=True)
    done = []
    for name in SHARED_FILES:
        src = shared / name
        dst = vdir / name
        if not src.exists():
            if dst.is_symlink():
                dst.unlink()
            continue
        target = os.path.relpath(src, vdir)
        if dst.is_symlink() and os.readlink(dst) == target:
            done.append(name)
            continue
        if dst.is_symlink() or dst.exists():
            dst.unlink()
        try:
            os.symlink(target, dst)
        except OSError:
            copy_file(src, dst)
        done.append(name)
    return done


def model_info(modal, modes_used: int | None, n_frequencies: int = 10) -> dict:
    """Size, frequencies and solver statistics of the modes the ``modal`` stage returned
    (its :class:`~railvib_hpc.modal.stage.ModesOutput`, computed or reused)."""
    freq = np.asarray(modal.frequencies_hz)
    info = {"n_nodes": int(modal.n_nodes),
            "n_hexes": None if modal.n_hexes is None else int(modal.n_hexes),
            "n_dofs": int(modal.n_dofs or 0)}
    m = int(modes_used or len(freq))
    info.update({"modes_in_file": len(freq), "modes_used": m,
                 "frequencies_hz": freq[:n_frequencies].tolist(),
                 "f_max_hz": float(freq[m - 1]),
                 "modal": dict(modal.solver_statistics)})
    return info


def mbs_metrics(passage) -> dict | None:
    """Contact-force and rail metrics of a passage: the result of the ``mbs`` stage
    (:class:`~railvib_hpc.mbs.stage.PassageOutput`) or of the ``transient`` stage
    (:class:`~railvib_hpc.transient.stage.TransientOutput`); None for a run without
    wheels (a case without a track, ``track.count = 0``: the moving load of ``[load]``
    has no contact force, wheel load or rail)."""
    peak = np.asarray(passage.peak_contact_force, dtype=float)
    if peak.size == 0:
        return None
    static = np.asarray(passage.static_wheel_load, dtype=float)
    ok = static > 0
    return {
        "peak_contact_force": float(peak.max()),
        "static_wheel_load": float(static.max()),
        "dynamic_increment": float((peak - static).max()),
        "dynamic_factor": float((peak[ok] / static[ok]).max()) if ok.any() else None,
        "min_contact_force": float(np.min(passage.min_contact_force)),
        "max_rail_deflection": float(passage.max_rail_deflection),
        "dt": float(passage.dt), "n_steps": int(passage.n_steps),
        "loss_of_contact_steps": int(passage.loss_of_contact_steps),
        "peak_per_wheel": peak.tolist(),
    }


def surface_load_info(case: Case) -> dict:
    """The loading of a case without a track (``track.count = 0``), for its ``result.json``
    (``load``): the moving load of ``[load]`` (force of each load [N], their number, speed
    [m/s], path ``y`` [m]); the result's ``mbs`` is None (no wheel, no rail)."""
    ld = case["load"]
    return {"type": "surface_load", "force": float(ld["force"]),
            "count": len(ld["offsets"]), "speed": float(ld["speed"]), "y": float(ld["y"])}


#: The compared quantity of a vehicle (:func:`response_quantities`); absent without a track.
CONTACT_FORCE = "peak contact force"


def all_with_contact_force(data: list[dict]) -> bool:
    """Whether every entry's ``quantities`` (:func:`response_quantities`) has the vehicle's
    contact force: False when some variant is a case without a track."""
    return all(CONTACT_FORCE in d["quantities"] for d in data)


def has_vehicle(result: dict) -> bool:
    """Whether a variant's result has a vehicle's metrics (``mbs``): False for a case
    without a track (the moving load of ``[load]``, :func:`surface_load_info`)."""
    return result.get("mbs") is not None


def probe_response(vdir: Path, case: Case, probes: Sequence[str]) -> dict:
    """Probe histories from the modes and their metrics (rank 0); writes ``probes.h5``.

    Parameters
    ----------
    vdir
        Variant folder with ``modes.h5`` and ``mbs.h5`` (and ``static.h5`` when the
        static correction is on).
    case
        The variant's case (``[assessment]`` settings).
    probes
        Probes whose assessment and spectra are kept (peaks are kept for every probe).

    Returns
    -------
    dict
        ``probes``, ``assessment``, ``spectra`` (see the module notes), ``n_steps``,
        ``duration``.
    """
    from ..io.formats.probes import write_probes_h5
    from ..reconstruct.probes import probe_histories
    from ..reconstruct.stage import read_inputs

    modes, mbs = vdir / MODES_H5, vdir / MBS_H5
    info = read_inputs(modes, mbs, correction_rates=case["output.static_correction_rates"])
    hist = probe_histories(modes, info["t"], info["q"], info["q_dot"], info["q_ddot"],
                           extra=info["extra"])
    missing = [p for p in probes if p not in hist]
    if missing:
        raise StudyError(f"study setting probes = {list(probes)}: {missing} are not probes "
                         f"of the mesh; available: {', '.join(hist)}")
    upstream = {n: file_digest(vdir / n).sha256 for n in (MODES_H5, STATIC_H5, MBS_H5)
                if (vdir / n).exists()}
    attrs = provenance(PROBES_H5, case, upstream, {"source": "study (from modes)",
                                                     "probes": "mesh"})
    attrs["source"] = "study (from modes)"
    write_probes_h5(vdir / PROBES_H5, hist, attrs=attrs)
    return response_metrics(hist, case, probes)


def response_metrics(hist: dict, case: Case, probes: Sequence[str]) -> dict:
    """Peaks of every probe, assessment and spectra of ``probes`` (see :func:`probe_response`)
    from probe histories ``{name: {t, displacement, velocity, acceleration, coords}}``."""
    from ..assess.standards import DIN4150_3_LOCATION_OF_ROLE, assess_probe
    from ..assess.weighting import third_octave_rms
    from ..reconstruct.probes import probe_peaks
    from ..schema import DEFAULT_PROBE_ROLE

    missing = [p for p in probes if p not in hist]
    if missing:
        raise StudyError(f"study setting probes = {list(probes)}: {missing} are not probes "
                         f"of the mesh; available: {', '.join(hist)}")
    t = next(iter(hist.values()))["t"]
    fs = 1.0 / float(np.median(np.diff(t))) if t.size > 1 else 1.0
    peaks, assessment, spectra = {}, {}, {}
    a_cfg = case["assessment"]
    for name, h in hist.items():
        a, v = h["acceleration"], h["velocity"]
        peaks[name] = probe_peaks(h, a_cfg["wave_threshold"])
        if name not in probes or t.size < 2:
            continue
        res = assess_probe(t, a, v, a_cfg["standards"], building_use=a_cfg["building_use"],
                           period=a_cfg["period"], fta_events=a_cfg["fta_events"],
                           din4150_3_location=DIN4150_3_LOCATION_OF_ROLE[
                               h.get("role") or DEFAULT_PROBE_ROLE],
                           din4150_2_events=a_cfg["din4150_2_events"] or None)
        utils = {s: b.get("utilisation") for s, b in res["standards"].items()}
        binding = [u for s, u in utils.items()
                   if u is not None and not res["standards"][s]["comparison_only"]]
        assessment[name] = {"passed": res["passed"], "utilisation": utils,
                            "max_utilisation": max(binding) if binding else None,
                            "metrics": {s: governing_metric(b)
                                        for s, b in res["standards"].items()}}
        spec = third_octave_rms(a, fs, fmin=ASSESSMENT_BAND_HZ[0],
                                fmax=ASSESSMENT_BAND_HZ[1], axis=0)
        ok = spec.n_bins > 0
        rms = spec.rms[ok]
        spectra[name] = {"bands_hz": spec.bands.nominal[ok].tolist(),
                         "acc_rms": {"x": rms[:, 0].tolist(), "y": rms[:, 1].tolist(),
                                     "z": rms[:, 2].tolist(),
                                     "total": np.sqrt((rms**2).sum(axis=1)).tolist()}}
    return {"probes": peaks, "assessment": assessment, "spectra": spectra,
            "n_steps": int(t.size), "duration": float(t[-1] - t[0]) if t.size else 0.0}


def governing_metric(block: dict) -> dict:
    """A standard's metric in its governing direction (the largest utilisation, or the
    largest value where no direction has a limit): ``metric``, ``unit``, ``direction``,
    ``value``, ``limit``, ``utilisation``, ``comparison_only``."""
    dirs = {d: e for d, e in (block.get("directions") or {}).items()
            if e.get("value") is not None}
    if not dirs:
        gov, entry = None, {}
    elif any(e.get("utilisation") is not None for e in dirs.values()):
        gov = max((d for d in dirs if dirs[d].get("utilisation") is not None),
                  key=lambda d: dirs[d]["utilisation"])
        entry = dirs[gov]
    else:
        gov = max(dirs, key=lambda d: dirs[d]["value"])
        entry = dirs[gov]
    return {"metric": block.get("metric"), "unit": block.get("unit"), "direction": gov,
            "value": entry.get("value"), "limit": entry.get("limit"),
            "utilisation": entry.get("utilisation"),
            "comparison_only": bool(block.get("comparison_only"))}


def prepare_shared(plan: StudyPlan, case: Case, root: Path, comm: MPI.Comm, rep: Reporter):
    """Compute (or reuse) the shared model of a study in ``<root>/model`` (collective);
    returns the ``modal`` stage's result (None when the study has no shared model)."""
    if plan.shared_overrides is None:
        return None
    mcase = on_root(lambda: variant_case(case, plan.shared_overrides), comm)
    command = f"railvib study {plan.kind}: shared model"
    runner = StageRunner(root / SHARED_DIR, comm, rep, command=command, wait=True)
    with runner.session(), rep.stage(f"{plan.kind}: shared model"):
        return run_stage(runner, "modal", mcase).result


def run_variant(plan: StudyPlan, v: Variant, case: Case, root: Path, comm: MPI.Comm, rep: Reporter,
                settings: dict[str, Any], wait: bool = False, compute=None) -> dict:
    """Run one variant (collective) unless it is finished; returns its result.

    ``compute``: the study's own computation of a variant (``Study.variant``,
    :mod:`.protocol`); None: the stages (the modal solution, or the full-order one with
    ``solver = direct``).

    Returns
    -------
    dict
        The result (``reused_result`` True when it was finished already), or
        ``{"failed": message}`` when a stage raised a user error (written to
        ``failed.json``; the study goes on with the other variants).
    """
    runner = StageRunner(root / v.name, comm, rep, wait=wait,
                         command=f"railvib study {plan.kind} --variant {v.name}")
    with runner.session(f"study {plan.kind} --variant {v.name}"):
        return _run_variant(plan, v, case, root, runner, settings, compute)


def _run_variant(plan: StudyPlan, v: Variant, case: Case, root: Path, runner: StageRunner,
                 settings: dict[str, Any], compute=None) -> dict:
    vdir, comm, rep = runner.out_dir, runner.comm, runner.rep

    def setup():
        vcase = variant_case(case, v.overrides)
        digest = variant_digest(plan.kind, vcase, settings)
        return vcase, digest, read_result(vdir, digest)

    vcase, digest, done = on_root(setup, comm)
    if done is not None:
        rep.info(f"[{plan.kind}/{v.name}] finished earlier: skipping ({vdir / RESULT_NAME})")
        return {**done, "reused_result": True}
    rep.info(f"[{plan.kind}/{v.name}] running: " + (", ".join(v.overrides) or "the case"))
    if compute is not None:
        return _run_own_variant(plan, v, vcase, digest, runner, settings, compute)
    if settings.get("solver") == "direct":
        return _run_direct_variant(plan, v, vcase, digest, runner, settings)
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    try:
        t0 = time.perf_counter()
        if v.shared:
            modal = prepare_shared(plan, case, root, comm, rep)   # reused when current
            on_root(lambda: link_shared(root / SHARED_DIR, vdir), comm)
            modes_reused = True
        else:
            if comm.rank == 0:
                vdir.mkdir(parents=True, exist_ok=True)
            if v.band_hz > 0:
                modal, vcase = _modes_for_band(vcase, runner, v.band_hz)
            else:
                modal = run_stage(runner, "modal", vcase).result
            modes_reused = bool(modal.reused)
        timings["modal"] = time.perf_counter() - t0
        passage = run_stage(runner, "mbs", vcase)
        mbs = passage.result
        timings["mbs"] = passage.seconds

        def finish() -> dict:
            t1 = time.perf_counter()
            resp = probe_response(vdir, vcase, settings["probes"])
            timings["response"] = time.perf_counter() - t1
            timings["total"] = time.perf_counter() - t_start
            result = {
                "schema": RESULT_FORMAT, "study": plan.kind, "variant": v.name,
                "parameter": v.parameter, "overrides": list(v.overrides),
                "inputs_sha256": digest, "railvib_version": __version__,
                "ranks": comm.size,
                "model": model_info(modal, vcase["mbs.n_modes"] or None),
                "mbs": mbs_metrics(mbs), **resp, "timings": timings,
                "reused": {"modes": modes_reused, "mbs": bool(mbs.reused)},
                "complete": True,
            }
            write_result(vdir, result, vcase)
            return result

        with rep.stage(f"{plan.kind}/{v.name}: probes + metrics"):
            result = on_root(finish, comm)
    except UserError as exc:
        return _record_failure(plan, v, digest, vdir, comm, rep, exc)
    return {**result, "reused_result": False}


def _record_failure(plan: StudyPlan, v: Variant, digest: str, vdir: Path, comm, rep: Reporter,
                    exc: UserError) -> dict:
    """Write ``failed.json`` for a variant that stopped with a user error."""
    msg = str(exc)

    def record() -> None:
        vdir.mkdir(parents=True, exist_ok=True)
        write_text(vdir / FAILED_NAME, json.dumps(
            {"study": plan.kind, "variant": v.name, "parameter": v.parameter,
             "overrides": list(v.overrides), "inputs_sha256": digest, "error": msg},
            indent=1))

    on_root(record, comm)
    rep.info(f"[{plan.kind}/{v.name}] FAILED: {msg}")
    return {"failed": msg, "variant": v.name}


def _run_own_variant(plan: StudyPlan, v: Variant, vcase: Case, digest: str,
                     runner: StageRunner, settings: dict[str, Any], compute) -> dict:
    """A variant computed by the study itself (``Study.variant``): its entries, with what
    every ``result.json`` holds (the study, the variant, the digest, the timings)."""
    vdir, comm, rep = runner.out_dir, runner.comm, runner.rep
    t_start = time.perf_counter()
    try:
        if comm.rank == 0:
            vdir.mkdir(parents=True, exist_ok=True)
        own = compute(plan, v, vcase, runner, settings)

        def finish() -> dict:
            result = {"schema": RESULT_FORMAT, "study": plan.kind, "variant": v.name,
                      "parameter": v.parameter, "overrides": list(v.overrides),
                      "inputs_sha256": digest, "railvib_version": __version__,
                      "ranks": comm.size, **own,
                      "timings": {**own.get("timings", {}),
                                  "total": time.perf_counter() - t_start},
                      "complete": True}
            write_result(vdir, result, vcase)
            return result

        result = on_root(finish, comm)
    except UserError as exc:
        return _record_failure(plan, v, digest, vdir, comm, rep, exc)
    return {**result, "reused_result": False}


def _run_direct_variant(plan: StudyPlan, v: Variant, vcase: Case, digest: str,
                        runner: StageRunner, settings: dict[str, Any]) -> dict:
    """A variant solved by the full-order time integration (the ``transient`` stage:
    reused when current, resumed from a current checkpoint)."""
    from ..io.formats.probes import read_probes

    vdir, comm, rep = runner.out_dir, runner.comm, runner.rep
    t_start = time.perf_counter()
    try:
        solved = run_stage(runner, "transient", vcase)
        stats = solved.result
        timings = {"transient": solved.seconds}

        def finish() -> dict:
            t1 = time.perf_counter()
            resp = response_metrics(read_probes(vdir / PROBES_H5), vcase, settings["probes"])
            timings["response"] = time.perf_counter() - t1
            timings["total"] = time.perf_counter() - t_start
            model = {"n_nodes": stats.n_nodes, "n_dofs": stats.n_dofs,
                     "n_hexes": None, "modes_in_file": None, "modes_used": None,
                     "frequencies_hz": [None],
                     # what the mesh resolves at the farthest probe (the transient stage's
                     # dispersion check), at most transient.f_max
                     "f_max_hz": stats.summary.get("resolved_up_to_hz",
                                                   vcase["transient.f_max"]),
                     "solver": "direct", "engine": stats.engine,
                     "dt": stats.dt, "n_steps": stats.n_steps,
                     "time_integration": stats.time_integration,
                     "peak_rss_gb_total": stats.peak_rss_gb_total}
            result = {
                "schema": RESULT_FORMAT, "study": plan.kind, "variant": v.name,
                "parameter": v.parameter, "overrides": list(v.overrides),
                "inputs_sha256": digest, "railvib_version": __version__, "ranks": comm.size,
                "model": model, "mbs": mbs_metrics(stats), **resp, "timings": timings,
                "reused": {"transient": bool(stats.reused)}, "complete": True}
            if vcase["track.count"] == 0:              # no vehicle: mbs is None
                result["load"] = surface_load_info(vcase)
            write_result(vdir, result, vcase)
            return result

        with rep.stage(f"{plan.kind}/{v.name}: probes + metrics"):
            result = on_root(finish, comm)
    except UserError as exc:
        return _record_failure(plan, v, digest, vdir, comm, rep, exc)
    return {**result, "reused_result": False}


def _modes_for_band(vcase: Case, runner: StageRunner, band_hz: float, attempts: int = 4):
    """Modal solve(s) until the modes reach ``band_hz``; the MBS case uses those below it.

    Returns
    -------
    tuple
        The ``modal`` stage's result and the case with ``mbs.n_modes`` = the number of
        modes below the band (and the final ``modal.n_modes``).
    """
    comm, rep = runner.comm, runner.rep
    case = vcase
    for _ in range(attempts):
        modal = run_stage(runner, "modal", case).result
        freq = modal.frequencies_hz.tolist()
        if case["modal.f_max"] >= band_hz:           # band-sliced: every mode below f_max
            rep.info(f"  {len(freq)} modes below the band limit {band_hz:g} Hz (inertia-"
                     "checked band solve)")
            k = len(freq)
            return modal, on_root(lambda c=case, k=k: variant_case(c, [f"mbs.n_modes={k}"]),
                                  comm)
        if freq[-1] >= band_hz:
            k = int(sum(f <= band_hz for f in freq))
            rep.info(f"  {k} of {len(freq)} modes lie below the band limit {band_hz:g} Hz")
            return modal, on_root(lambda c=case, k=k: variant_case(c, [f"mbs.n_modes={k}"]),
                                  comm)
        n = len(freq)
        more = int(math.ceil(n * (band_hz / freq[-1]) ** 3 * 1.15)) + 8
        rep.info(f"  {n} modes end at {freq[-1]:.2f} Hz < {band_hz:g} Hz: solving again "
                 f"with {more} modes")
        case = on_root(lambda c=case, m=more: variant_case(c, [f"modal.n_modes={m}"]), comm)
    raise StudyError(f"the modes did not reach {band_hz:g} Hz after {attempts} solves")


def band_resolved(nominal_hz: float, f_max_hz: float | None) -> bool:
    """Whether a one-third-octave band (nominal centre) lies in a solution's band
    ``f_max_hz`` -- the convention of :func:`~railvib_hpc.assess.weighting.
    third_octave_bands` and ``transient.f_max`` (80 Hz: the 80 Hz band is the top one)."""
    return f_max_hz is None or float(nominal_hz) <= float(f_max_hz) * (1 + 1e-9)


def resolved_up_to(result: dict) -> float | None:
    """The highest frequency a variant's solution resolves [Hz]: its highest mode used
    (modal), ``transient.f_max`` or less where the mesh does not resolve it at the
    farthest probe (``solver = direct``: the transient stage's dispersion check); None
    when unknown."""
    f = (result.get("model") or {}).get("f_max_hz")
    return float(f) if f is not None else None


def resolved_spectra(result: dict) -> dict:
    """``result`` with its spectra cut to the one-third-octave bands its solution resolves
    (nominal centre at most :func:`resolved_up_to`, :func:`band_resolved`); the bands left
    out are listed in ``unresolved_bands_hz`` ``{probe: [nominal Hz]}``. The result itself
    is not changed."""
    top = resolved_up_to(result)
    if top is None or not result.get("spectra"):
        return result
    spectra, dropped = {}, {}
    for probe, spec in result["spectra"].items():
        if not spec:
            spectra[probe] = spec
            continue
        keep = [i for i, f in enumerate(spec["bands_hz"]) if band_resolved(f, top)]
        kept = set(keep)
        spectra[probe] = {**spec, "bands_hz": [spec["bands_hz"][i] for i in keep],
                          "acc_rms": {c: [vals[i] for i in keep]
                                      for c, vals in spec["acc_rms"].items()},
                          "resolved_up_to_hz": top}
        gone = [f for i, f in enumerate(spec["bands_hz"]) if i not in kept]
        if gone:
            dropped[probe] = gone
    return {**result, "spectra": spectra, "unresolved_bands_hz": dropped}


def band_coverage(plan: StudyPlan, results: dict[str, dict]) -> dict:
    """Which frequencies the finished variants resolve, against the assessment band.

    Returns
    -------
    dict
        ``assessment_band_hz`` ``[low, high]``; ``variants``: per finished variant its
        ``solver``, ``engine`` (``transient.engine`` of a direct variant, else None),
        ``modes`` used, lowest natural frequency ``f1_hz`` (modal) and
        ``f_max_hz`` (highest mode used, or ``transient.f_max``), ``top_band_hz`` (the
        highest one-third-octave band reported); ``f_max_hz``: the lowest of them;
        ``warning``: a sentence when a variant's band ends below the top of the assessment
        band (else None).
    """
    lo, hi = ASSESSMENT_BAND_HZ
    per = []
    for v in plan.variants:
        r = results.get(v.name)
        if r is None or "model" not in r:       # (a study's own variants: no solution band)
            continue
        m = r.get("model") or {}
        direct = m.get("solver") == "direct"
        freqs = [f for f in (m.get("frequencies_hz") or []) if f is not None]
        top = resolved_up_to(r)
        bands = [f for f in _third_octave_nominals(lo, hi) if band_resolved(f, top)]
        per.append({"variant": v.name, "solver": "direct" if direct else "modal",
                    "engine": m.get("engine", "direct") if direct else None,
                    "modes": m.get("modes_used"), "f1_hz": None if direct or not freqs
                    else freqs[0], "f_max_hz": top,
                    "top_band_hz": bands[-1] if bands else None})
    tops = [p for p in per if p["f_max_hz"] is not None]
    short = [p for p in tops if not band_resolved(hi, p["f_max_hz"])]
    warning = None
    if short:
        worst = min(short, key=lambda p: p["f_max_hz"])
        direct = worst["solver"] == "direct"
        what = ("transient.f_max, or less where the mesh does not resolve it" if direct else
                f"{worst['modes']} modes, {fmt_hz(worst['f1_hz'])}–"
                f"{fmt_hz(worst['f_max_hz'])} Hz")
        remedy = (f"a finer soil mesh (mesh.wavelength_hz = {hi:g}, or a spectral order) "
                  f"and transient.f_max = {hi:g}" if direct else
                  f"more modes (e.g. modal.f_max = {hi:g}) or solver = direct")
        warning = (f"the solution of {len(short)} of {len(per)} finished variants does not "
                   f"cover the assessment band {lo:g}–{hi:g} Hz ({worst['variant']}: "
                   f"{what}, resolved up to {fmt_hz(worst['f_max_hz'])} Hz): one-third-octave "
                   "bands above a variant's band are not reported, and its peaks and "
                   f"assessment miss the response above {fmt_hz(worst['f_max_hz'])} Hz; use "
                   f"{remedy}")
    return {"assessment_band_hz": [lo, hi], "variants": per,
            "f_max_hz": min((p["f_max_hz"] for p in tops), default=None), "warning": warning}


def fmt_hz(f: float | None) -> str:
    """A frequency for a sentence (``'–'`` when unknown)."""
    return "–" if f is None else f"{f:.3g}"


def _third_octave_nominals(lo: float, hi: float) -> list[float]:
    from ..assess.weighting import third_octave_bands

    return [float(f) for f in third_octave_bands(lo, hi).nominal]


def relative(a: float | None, b: float | None) -> float | None:
    """``|a - b| / |b|`` or None."""
    if a is None or b is None or not math.isfinite(a) or not math.isfinite(b) or b == 0:
        return None
    return abs(a - b) / abs(b)


def response_quantities(result: dict, probes: Sequence[str]) -> dict[str, float]:
    """The compared response quantities of a result: building peaks and contact force.

    Keys: ``<probe> a_z`` and ``<probe> |a|`` (peak vertical and total acceleration [m/s²])
    for each probe, ``peak contact force`` [N] (left out for a case without a track: no
    vehicle, :func:`has_vehicle`).
    """
    out: dict[str, float] = {}
    for p in probes:
        pk = result["probes"][p]
        out[f"{p} a_z"] = pk["acc_vertical"]
        out[f"{p} |a|"] = pk["acc_total"]
    if has_vehicle(result):
        out[CONTACT_FORCE] = result["mbs"]["peak_contact_force"]
    return out
