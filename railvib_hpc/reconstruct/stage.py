"""The ``reconstruct`` stage: modes.h5 + mbs.h5 -> fields, stresses, probes (collective).

Inputs
------
``modes.h5`` (complete, see :mod:`railvib_hpc.io.formats.modes`) and ``mbs.h5``::

    /time                 (nt,)     strictly increasing [s]
    /modal/q              (nt, m)   modal coordinates of the first m modes (m <= modes)
    /modal/q_dot          (nt, m)
    /modal/q_ddot         (nt, m)
    /static               optional static correction, attrs basis_file (path relative to
                          mbs.h5's folder) and basis (dataset name of a (k, n, 3) basis
                          there), datasets g, g_dot, g_ddot (nt, k)
    attrs: complete = 1

Everything is validated on rank 0 and a :class:`ReconstructInputError` naming the file,
dataset and shape is raised on every rank together.

Outputs (in ``out_dir``)
------------------------
* ``fields.h5`` + ``fields.xdmf`` (+ its views ``fields_views.h5``): displacement,
  velocity, acceleration of every node at every ``stride``-th step of the time ``window``
  (:mod:`.fields`);
* ``/stress`` in ``fields.h5`` + ``stress.xdmf`` (+ ``stress_views.h5``) when
  ``stress_times`` are given (:mod:`.stress`). With new fields the stresses are written
  into the temporary file before it is renamed (fields and stresses are one atomic
  result); when only the stress times changed they are rewritten in place in the reused
  ``fields.h5`` (attribute ``stress_complete`` is 0 while that happens);
* ``probes.h5`` + ``probes/<name>.csv``: histories of the mesh probes and the user probes
  at every step of the window (full time resolution: probes are cheap), and in
  ``probes.h5`` ``/rail``: the vertical bending moment of every rail (r = 2 per track, by
  increasing y; modal part only, the static correction has no rotations), sagging positive
  (:func:`.stress.rail_bending_moment`): ``time`` (nt,), ``x`` (r, k), ``y`` (r,), ``nodes``
  (r, k), ``bending_moment`` (nt, r, k) at the nodes (averaged where it jumps) and
  ``bending_moment_ends`` (nt, r, k-1, 2) at both ends of every rail element (exact; the
  jump at a node is the reaction moment where the rail rotations are fixed at the pads).

Reuse
-----
Each product records its provenance (:mod:`railvib_hpc.io.provenance`): the inputs hash
of the case keys and options it depends on and the content digests of ``modes.h5``,
``mbs.h5`` and the static basis it was computed from. A complete ``fields.h5`` (and
``/stress``, ``probes.h5``) with the same inputs and upstream digests whose content is
unchanged and sound is reused and reported; anything else is recomputed, saying why.

Entry points
------------
:func:`run_reconstruct_stage` (``railvib reconstruct``) takes the case: it verifies that
``modes.h5``, ``mbs.h5`` (and ``static.h5``) are current for it (else it refuses, naming
the file and what differs), derives the options from ``[output]`` and calls
:func:`reconstruct_outputs`, which works on any pair of files (no case).
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import UserError
from ..io.atomic import ensure_space
from ..io.digests import digest, file_digest, record_file
from ..io.files import (
    FIELDS_H5,
    FIELDS_XDMF,
    MBS_H5,
    MODES_H5,
    PROBES_CSV_DIR,
    PROBES_H5,
    STATIC_H5,
    STRESS_XDMF,
)
from ..io.formats.checks import open_input, text_attr
from ..io.formats.fields import FieldsFile, check_fields
from ..io.formats.mbs import MbsFile, MbsFileError, passage_inputs
from ..io.formats.probes import check_probes, write_probes_csv, write_probes_h5
from ..io.products import Selection, StageFile
from ..io.stage_outputs import FieldsOutput
from ..io.stage_protocol import Stage, StageContext, StageRunner
from ..io.xdmf import ensure_views, remove_xdmf
from ..log import Reporter
from ..modal.refusals import needs_track
from ..parallel import on_root
from ..site import line_probes
from .fields import reconstruct_fields, write_fields_xdmf
from .probes import UserProbes, locate_probes, probe_histories, user_probe_dict
from .stress import (
    hex_materials,
    rail_moment_history,
    rail_moment_modes,
    stress_from_fields,
    write_stress_xdmf,
)

if TYPE_CHECKING:
    from mpi4py import MPI


class ReconstructInputError(UserError):
    """Missing, incomplete or inconsistent input of the reconstruct stage."""


def _dataset(f, path: Path, name: str):
    if name not in f:
        raise ReconstructInputError(f"{path}: dataset '{name}' is missing")
    ds = f[name]
    if not hasattr(ds, "shape"):
        raise ReconstructInputError(f"{path}: '{name}' is a group, expected a dataset")
    return ds


def read_inputs(modes_path: Path, mbs_path: Path, stride: int = 1,
                window: tuple[float, float] | None = None,
                correction_rates: bool = False) -> dict:
    """Validate ``modes.h5`` and ``mbs.h5`` and read the histories of the time window (serial).

    With a static correction in ``mbs.h5`` the displacement coordinates are always
    corrected (``q + q_shift`` and the static basis with ``g``); the velocity and
    acceleration coordinates only when ``correction_rates`` (otherwise they are the
    modes' own ``q_dot``, ``q_ddot`` and the static basis gets ``g_dot = g_ddot = 0``:
    the classical mode-acceleration method).

    Returns
    -------
    dict
        ``t``, ``q``, ``q_dot``, ``q_ddot`` of the window (full resolution), ``first`` (index
        of the window's first step in ``mbs.h5``), ``steps`` (stored steps, relative to
        the window), ``extra`` (list of static bases with their ``g`` histories of the
        window), ``m``, ``k``, ``n_nodes``, ``n_modes``, digests ``modes_key``, ``mbs_key``,
        ``static_key``, and ``rails`` (True when the modes have flexible-rail nodes).

    Raises
    ------
    ReconstructInputError
        With the file, dataset and shape at fault.
    """
    if int(stride) != stride or stride < 1:
        raise ReconstructInputError(f"stride must be a positive integer, got {stride!r}")
    with open_input(modes_path, "modes file", ReconstructInputError) as f:
        if int(text_attr(f, "complete", 0)) != 1:
            raise ReconstructInputError(f"{modes_path} is incomplete (attribute complete != 1);"
                                        " rerun the modal stage")
        trans = _dataset(f, modes_path, "modes/translation")
        if trans.ndim != 3 or trans.shape[2] != 3:
            raise ReconstructInputError(f"{modes_path}: modes/translation has shape "
                                        f"{trans.shape}, expected (m, n, 3)")
        n_modes, n = trans.shape[0], trans.shape[1]
        for name in ("mesh/points", "mesh/hexes", "mesh/hex_part"):
            _dataset(f, modes_path, name)
        n_hexes = f["mesh/hexes"].shape[0]
        modes_key = file_digest(modes_path).sha256
        rails = "mesh/rail_nodes" in f and f["mesh/rail_nodes"].size > 0 \
            and "case_toml" in f.attrs and "modes/rotation" in f
    try:
        w = MbsFile(mbs_path).window(n_modes, n, window, correction_rates,
                                     modes_name=str(modes_path))
    except MbsFileError as exc:
        raise ReconstructInputError(str(exc)) from None
    mbs_key = file_digest(mbs_path).sha256
    extra = [w.static] if w.static is not None else []
    static_key = file_digest(Path(w.static[0])).sha256 if w.static is not None else ""
    i0, i1, m, k = w.first, w.first + w.t.size, w.m, w.k
    steps = np.arange(0, i1 - i0, int(stride))
    return {"t": w.t, "q": w.q, "q_dot": w.q_dot, "q_ddot": w.q_ddot, "first": i0,
            "steps": steps, "extra": extra, "m": m, "k": k, "n_nodes": n, "n_modes": n_modes,
            "modes_key": modes_key, "mbs_key": mbs_key, "static_key": static_key,
            "static_file": extra[0][0] if extra else "", "rails": bool(rails),
            "n_hexes": int(n_hexes)}


def _upstream(info: dict) -> dict[str, str]:
    """Content digests of the files the outputs are computed from."""
    up = {MODES_H5: info["modes_key"], MBS_H5: info["mbs_key"]}
    if info["static_key"]:
        up[Path(info["static_file"]).name] = info["static_key"]
    return up


def _options(info: dict, stride: int, window, float32: bool, stress_times, user_probes,
             user_roles, correction_rates: bool) -> dict:
    """The options of each product (part of its inputs hash)."""
    base = {"m": info["m"], "k": info["k"],
            "window": None if window is None else [float(v) for v in window],
            "rates": bool(correction_rates) if info["k"] else False}
    fields = {**base, "stride": int(stride), "float32": bool(float32)}
    return {"fields": fields,
            "stress": {"times": [float(v) for v in stress_times]},
            "probes": {**base, "probes": {k: v.tolist() for k, v in
                                          user_probe_dict(user_probes).items()},
                       "roles": dict(user_roles or {})}}


def _expected(case, options: dict) -> dict:
    """Inputs hashes of fields.h5, its /stress and probes.h5 (with or without a case)."""
    def one(name: str, opts: dict) -> str:
        if case is None:
            return digest({"file": name, "options": opts})
        from ..io.products import inputs_hash

        return inputs_hash(case, name, opts)

    fields = one(FIELDS_H5, options["fields"])
    return {"fields": fields, "stress": digest({"fields": fields, **options["stress"]}),
            "probes": one(PROBES_H5, options["probes"])}


def _refresh_xdmf(xdmf: Path, write, comm, rep: Reporter) -> None:
    """Rewrite the XDMF file of a reused data file when it has the earlier form."""
    if on_root(lambda: ensure_views(xdmf, write), comm):
        rep.info(f"rewrote {xdmf} (per-step views for both ParaView XDMF readers)")


def _reusable(ctx: StageContext, keys: dict, upstream: dict, want_stress: bool) -> dict:
    """Which outputs in the context's folder are current and sound (rank 0); says why not."""

    out_dir = ctx.out_dir
    ok = {"fields": False, "stress": False, "probes": False}
    fields = out_dir / FIELDS_H5
    ok["fields"] = ctx.reuse(FIELDS_H5, path=fields, inputs_sha256=keys["fields"],
                             upstream=upstream).ok
    if ok["fields"] and want_stress:
        try:
            ok["stress"] = (FieldsFile(fields).stress_current(keys["stress"])
                            and (out_dir / STRESS_XDMF).is_file())
        except (OSError, KeyError):
            ok["stress"] = False
    ok["probes"] = ctx.reuse(PROBES_H5, path=out_dir / PROBES_H5,
                             inputs_sha256=keys["probes"], upstream=upstream).ok
    return ok


def reconstruct_options(case, out_dir: Path) -> dict:
    """Stride, window, precision, stress times and user probes from ``[output]`` (rank 0;
    the stride is ``output.dt`` over the step of ``mbs.h5``)."""
    mbs = out_dir / MBS_H5
    stride = 1
    if mbs.exists() and case["output.dt"] > 0:
        dt = MbsFile(mbs).time_step()
        if dt is not None:
            stride = max(1, int(round(case["output.dt"] / dt)))
    w = case["output.window"]
    probes = np.asarray(case["output.probes"], dtype=float).reshape(-1, 3)
    names = [f"user_{i + 1}" for i in range(len(probes))]
    lines = line_probes(case)                      # [[probes.line]]: free-field points
    return {"stride": stride, "window": tuple(w) if w else None,
            "float32": case["output.float32"], "stress_times": case["output.stress_times"],
            "correction_rates": case["output.static_correction_rates"],
            "user_probes": {**dict(zip(names, probes)),
                            **{n: np.asarray(p.point, dtype=float) for n, p in lines.items()}},
            "user_probe_roles": {**dict(zip(names, case["output.probe_roles"])),
                                 **{n: "free_field" for n in lines}}}


def input_files(out_dir: Path) -> tuple[str, ...]:
    """The stage files the reconstruction reads (``static.h5`` when ``mbs.h5`` has a
    static correction; :func:`~railvib_hpc.io.formats.mbs.passage_inputs`)."""
    return passage_inputs(out_dir)


def compute(ctx: StageContext) -> FieldsOutput:
    """``railvib reconstruct``: fields, stresses and probes of the case (collective).

    Verifies that ``modes.h5``, ``mbs.h5`` (and ``static.h5``) in the folder are current
    for the case and sound (else :class:`~railvib_hpc.errors.StaleInputError` naming the
    file, what differs and the command to run), takes the options from ``[output]`` and
    reconstructs (as :func:`reconstruct_outputs`).
    """
    case, out_dir = ctx.case, ctx.out_dir

    def prepare() -> dict:
        names = input_files(out_dir)
        ctx.input("modal", names[:-1])          # modes.h5 (static.h5), then mbs.h5
        ctx.input("mbs", names[-1:])
        return reconstruct_options(case, out_dir)

    opts = on_root(prepare, ctx.comm)
    summary = _outputs(ctx, out_dir / MODES_H5, out_dir / MBS_H5, **opts)

    def output() -> FieldsOutput:
        from ..io.formats.probes import read_probes
        from .probes import probe_peaks

        def present(name: str) -> Path | None:
            return out_dir / name if (out_dir / name).exists() else None

        threshold = case["assessment.wave_threshold"]
        peaks = {name: {"role": h["role"], **probe_peaks(h, threshold)}
                 for name, h in read_probes(out_dir / PROBES_H5).items()}
        return FieldsOutput(reused=summary.get("reused"), summary=summary,
                            fields_h5=out_dir / FIELDS_H5, fields_xdmf=present(FIELDS_XDMF),
                            stress_xdmf=present(STRESS_XDMF)
                            if case["output.stress_times"] else None,
                            probes_h5=out_dir / PROBES_H5, probes=peaks)

    return on_root(output, ctx.comm)


#: The fields' case keys beyond the passage's (the rows extend ``mbs.h5``'s): the output
#: steps and window, the precision and the static correction's rates.
FIELDS_KEYS: Selection = (("output.dt", ()), ("output.window", ()), ("output.float32", ()),
                          ("output.static_correction_rates", ()))
#: The probes' case keys beyond the passage's: the window, the probes and [probes].
PROBES_KEYS: Selection = (("output.window", ()), ("output.probes", ()),
                          ("output.static_correction_rates", ()), ("probes", ()))
#: The products: ``fields.h5`` (and its XDMF view) and ``probes.h5``, computed from the
#: modes and the passage (and the static fields with the static correction).
PRODUCTS = (
    StageFile(FIELDS_H5, "reconstruct", 2, FIELDS_KEYS, (MODES_H5, MBS_H5, STATIC_H5),
              (FIELDS_XDMF,), ("mesh.file", "irregularity.file"), check=check_fields,
              extends=(MBS_H5,)),
    StageFile(PROBES_H5, "reconstruct", 2, PROBES_KEYS, (MODES_H5, MBS_H5, STATIC_H5), (),
              ("mesh.file", "irregularity.file"), check=check_probes, extends=(MBS_H5,)),
)

STAGE = Stage(name="reconstruct", help="rebuild displacement/velocity/acceleration fields of "
              "every node", products=PRODUCTS, reads=(MODES_H5, STATIC_H5, MBS_H5),
              compute=compute, needs=("modal", "mbs"), refuse=needs_track)


def run_reconstruct_stage(case, out_dir: str | os.PathLike, comm: MPI.Comm, rep: Reporter,
                          petsc_options: list[str] | None = None) -> dict:
    """The ``reconstruct`` stage from a script: :data:`STAGE` through the runner (the
    folder's lock; no ``run.json`` entry). Returns its summary (every rank)."""
    runner = StageRunner(out_dir, comm, rep, petsc_options or (), command="reconstruct")
    return dict(runner.run(STAGE, case, record=False).result.summary)


def reconstruct_outputs(modes_path: str | os.PathLike, mbs_path: str | os.PathLike,
                        out_dir: str | os.PathLike, comm: MPI.Comm, rep: Reporter, *,
                        stride: int = 1,
                        window: tuple[float, float] | None = None, float32: bool = False,
                        stress_times: Sequence[float] = (), user_probes: UserProbes = (),
                        user_probe_roles: Mapping[str, str] | None = None,
                        correction_rates: bool = False, case=None) -> dict:
    """Reconstruct fields, stresses and probe histories (collective; reuses what it can).

    Parameters
    ----------
    modes_path
        A complete ``modes.h5``.
    mbs_path
        A complete ``mbs.h5`` (layout in the module docstring).
    out_dir
        Output folder (created).
    comm
        MPI communicator.
    rep
        Reporter (stage timings, progress).
    stride
        Store every ``stride``-th step of the window in ``fields.h5``.
    window
        ``(t_start, t_end)`` [s], inclusive; all steps by default.
    float32
        Store the fields in single precision (half the size).
    stress_times
        Times [s] at which element stresses are computed (nearest stored steps).
    user_probes
        Extra probe points, ``{name: (x, y, z)}`` or a list of ``(x, y, z)``.
    user_probe_roles
        Their roles by name (:data:`railvib_hpc.schema.PROBE_ROLES`; missing: ``ground``).
    correction_rates
        Add a static correction also to velocities and accelerations (see
        :func:`read_inputs`).
    case
        The case the outputs belong to (their provenance); None for files outside a case
        (the inputs hash then covers the options only).

    Returns
    -------
    dict
        ``reused`` (per output), ``fields`` / ``stress`` / ``probes`` statistics, ``seconds``
        (per part and total) and the flat keys ``gemm_gflops``, ``write_gb_per_s``,
        ``bytes_written`` for a timing table.

    Raises
    ------
    ReconstructInputError
        Invalid inputs (on every rank).
    """
    runner = StageRunner(out_dir, comm, rep, command="reconstruct")
    with runner.session():
        return _outputs(runner.context(case), modes_path, mbs_path,
                        stride=stride, window=window, float32=float32,
                        stress_times=stress_times, user_probes=user_probes,
                        user_probe_roles=user_probe_roles, correction_rates=correction_rates)


def _outputs(ctx: StageContext, modes_path: str | os.PathLike, mbs_path: str | os.PathLike, *,
             stride: int = 1, window: tuple[float, float] | None = None, float32: bool = False,
             stress_times: Sequence[float] = (), user_probes: UserProbes = (),
             user_probe_roles: Mapping[str, str] | None = None,
             correction_rates: bool = False) -> dict:
    """:func:`reconstruct_outputs` into the context's folder (the runner holds its lock)."""
    t_start = time.perf_counter()
    case, out_dir, comm, rep = ctx.case, ctx.out_dir, ctx.comm, ctx.rep
    modes_path, mbs_path = Path(modes_path), Path(mbs_path)
    stress_times = [float(v) for v in np.atleast_1d(np.asarray(stress_times, dtype=float))]
    full: dict = {}

    def load():
        info = read_inputs(modes_path, mbs_path, stride, window, correction_rates)
        user = user_probe_dict(user_probes)     # validate the coordinates early
        if user:
            locate_probes(modes_path, np.array(list(user.values())), list(user))
        full.update(info)
        options = _options(info, stride, window, float32, stress_times, user_probes,
                           user_probe_roles, correction_rates)
        keys = _expected(case, options)
        upstream = _upstream(info)
        out_dir.mkdir(parents=True, exist_ok=True)
        reuse = _reusable(ctx, keys, upstream, bool(stress_times))
        attrs = {n: ctx.provenance(f"{n}.h5", upstream, options[n],
                                   inputs_sha256=keys[n] if case is None else None)
                 for n in ("fields", "probes")}
        if stress_times:
            t_sel = info["t"][info["steps"]]
            tol = 1e-9 * max(1.0, float(np.abs(t_sel).max()))
            bad = [v for v in stress_times if v < t_sel[0] - tol or v > t_sel[-1] + tol]
            if bad:
                raise ReconstructInputError(f"stress times {bad} are outside the stored time "
                                            f"range [{t_sel[0]}, {t_sel[-1]}] s")
        small = {k: v for k, v in info.items() if k not in ("t", "q", "q_dot", "q_ddot",
                                                            "extra")}
        if not reuse["fields"]:                 # every rank needs the stored rows
            s = info["steps"]
            small.update({"t": info["t"][s], "q": info["q"][s], "q_dot": info["q_dot"][s],
                          "q_ddot": info["q_ddot"][s],
                          "extra": [(e[0], e[1], e[2][s], e[3][s], e[4][s])
                                    for e in info["extra"]]})
        return small, keys, reuse, attrs

    return _reconstruct(load, modes_path, mbs_path, out_dir, comm, rep, stress_times,
                        user_probes, user_probe_roles, float32, stride, window, full, t_start)


def _reconstruct(load, modes_path: Path, mbs_path: Path, out_dir: Path, comm: MPI.Comm,
                 rep: Reporter, stress_times, user_probes, user_probe_roles, float32: bool,
                 stride: int, window, full: dict, t_start: float) -> dict:
    info, keys, reuse, attrs = on_root(load, comm)
    fields_path = out_dir / FIELDS_H5
    result: dict = {"reused": dict(reuse), "seconds": {}}

    # ---- fields
    if reuse["fields"]:
        rep.info(f"reusing {fields_path} (same modes, histories and options)")
        result["fields"] = on_root(lambda: _fields_summary(fields_path), comm)
        _refresh_xdmf(out_dir / FIELDS_XDMF, lambda: write_fields_xdmf(fields_path), comm,
                      rep)
    else:
        with rep.stage("reconstruct fields"):
            t0 = time.perf_counter()
            ns = len(info["steps"])
            rep.info(f"  {info['n_nodes']} nodes x {ns} steps x {info['m']} modes"
                     + (f" + {info['k']} static shapes" if info["k"] else "")
                     + f" on {comm.size} rank(s)")
            stress_stats: dict = {}

            def add_stress(tmp: Path) -> None:
                # stresses go into the temporary file: fields + stresses are one atomic result
                t1 = time.perf_counter()
                stress_stats.update(_stress(tmp, modes_path, comm, stress_times, rep, keys, True))
                stress_stats["seconds"] = time.perf_counter() - t1

            stats = reconstruct_fields(
                modes_path, fields_path, comm, info["t"], info["q"], info["q_dot"],
                info["q_ddot"], float32=float32, extra=info["extra"], rep=rep,
                attrs={**attrs["fields"], "mbs_file": mbs_path.name, "stride": int(stride),
                       "window": json.dumps(None if window is None else list(window))},
                step_numbers=info["first"] + info["steps"],
                before_complete=add_stress if stress_times else None,
                extra_bytes=_stress_bytes(info, stress_times))
            result["seconds"]["fields"] = time.perf_counter() - t0
            result["fields"] = stats
            rep.info(f"  wrote {stats['bytes_written'] / 1e9:.3f} GB: GEMM "
                     f"{stats['seconds_gemm']:.2f} s ({stats['gemm_gflops']:.1f} GFlop/s), "
                     f"write {stats['seconds_write']:.2f} s "
                     f"({stats['write_gb_per_s']:.2f} GB/s), read modes "
                     f"{stats['seconds_read']:.2f} s")
        if stress_times:
            result["stress"] = stress_stats
            result["seconds"]["stress"] = stress_stats["seconds"]
            result["seconds"]["fields"] -= stress_stats["seconds"]
        elif comm.rank == 0:                     # a new fields.h5 has no /stress
            remove_xdmf(out_dir / STRESS_XDMF)

    # ---- stresses of reused fields: written into the existing fields.h5
    if stress_times and reuse["fields"]:
        if reuse["stress"]:
            rep.info(f"reusing /stress of {fields_path}")
            _refresh_xdmf(out_dir / STRESS_XDMF, lambda: write_stress_xdmf(fields_path),
                          comm, rep)
        else:
            with rep.stage("reconstruct stress"):
                t0 = time.perf_counter()
                # rewritten in place: the record no longer matches until it is renewed
                on_root(lambda: ensure_space(out_dir, _stress_bytes(info, stress_times),
                                             "the stresses of fields.h5"), comm)
                result["stress"] = _stress(fields_path, modes_path, comm, stress_times, rep,
                                           keys, False)
                record_file(fields_path, comm)
                result["seconds"]["stress"] = time.perf_counter() - t0

    # ---- probes and rail moments (rank 0)
    if reuse["probes"]:
        rep.info(f"reusing {out_dir / PROBES_H5}")
    else:
        with rep.stage("reconstruct probes"):
            t0 = time.perf_counter()
            result["probes"] = on_root(lambda: _probes(modes_path, out_dir, full, user_probes,
                                                       user_probe_roles, attrs["probes"]),
                                       comm)
            result["seconds"]["probes"] = time.perf_counter() - t0
            rep.info(f"  {result['probes']['n_probes']} probes x {result['probes']['n_steps']}"
                     f" steps -> {out_dir / PROBES_H5}, {out_dir / PROBES_CSV_DIR}/*.csv")
    result["seconds"]["total"] = time.perf_counter() - t_start
    fstats = result.get("fields") or {}
    for key in ("gemm_gflops", "write_gb_per_s", "bytes_written"):
        result[key] = fstats.get(key)
    return result


def _stress_bytes(info: dict, stress_times) -> int:
    """Size of ``/stress`` (von Mises and equivalent strain per hexahedron and time)."""
    return 16 * len(stress_times) * int(info.get("n_hexes", 0)) + 16 * len(stress_times)


def _stress(path: Path, modes_path: Path, comm: MPI.Comm, stress_times, rep: Reporter, keys,
            temporary: bool) -> dict:
    materials = on_root(lambda: _materials(modes_path), comm)
    stats = stress_from_fields(path, comm, stress_times, materials, rep=rep,
                               attrs={"inputs_sha256": keys["stress"]},
                               require_complete=not temporary)
    rep.info(f"  stresses at {len(stress_times)} time(s), max von Mises "
             f"{stats['max_von_mises'] / 1e3:.3f} kPa")
    return stats


def _fields_summary(path: Path) -> dict:
    import h5py

    with h5py.File(path, "r") as f:
        d = f["fields/displacement"]
        return {"n_nodes": d.shape[1], "n_steps": d.shape[0], "n_modes": int(f.attrs["n_modes"]),
                "n_extra": int(f.attrs["n_extra"]), "float32": bool(f.attrs["float32"]),
                "bytes_written": 3 * d.size * d.dtype.itemsize}


def _materials(modes_path: Path) -> dict:
    import h5py

    from ..problem import Problem

    with h5py.File(modes_path, "r") as f:
        if "case_toml" not in f.attrs:
            raise ReconstructInputError(f"{modes_path} has no case_toml attribute: the "
                                        "materials for the stresses are unknown")
        return hex_materials(Problem.from_modes(f))


def _probes(modes_path: Path, out_dir: Path, info: dict, user_probes, user_roles,
            prov: dict) -> dict:
    """Rank 0: probe histories (full resolution of the window) and rail moments."""
    t = info["t"]
    hist = probe_histories(modes_path, t, info["q"], info["q_dot"], info["q_ddot"],
                           user_probes=user_probes, user_roles=user_roles,
                           extra=info["extra"])
    groups = {}
    if info["rails"]:
        rail = rail_moment_modes(modes_path, info["m"])
        groups["rail"] = {"time": t, "x": rail["x"], "y": rail["y"], "nodes": rail["nodes"],
                          "bending_moment": rail_moment_history(info["q"], rail["moment"]),
                          "bending_moment_ends": rail_moment_history(info["q"],
                                                                     rail["moment_ends"])}
    attrs = {**prov, "rail_moment_sign": "sagging positive (M = E I dpsi/dx, psi = -ry)",
             "rail_moment_static_correction_included": 0}
    write_probes_h5(out_dir / PROBES_H5, hist, attrs=attrs, groups=groups)
    write_probes_csv(out_dir / PROBES_CSV_DIR, hist)
    return {"n_probes": len(hist), "n_steps": len(t), "names": list(hist),
            "rail_moment": bool(groups)}
