"""Stage files: the one place that knows how railvib's results are written, recorded and reused.

Every stage writes its results into the output folder ``<out>`` and a later run reuses
them only when they are provably the ones the current case asks for. This module holds
that whole protocol; the stages call it and never write their own reuse logic.

The table of stage files
------------------------
:data:`STAGE_FILES` names, for each result file, the command that writes it, its format
version, the case keys it depends on (cumulatively: a file depends on everything its
upstream files depend on) and the upstream files it reads:

===============  ===========  ==========================================  ===================
file             written by   case keys (inputs)                          upstream files
===============  ===========  ==========================================  ===================
mesh.h5          mesh         geometry, track, building, mesh, domain,    --
                              the content of ``mesh.file``
modes.h5         modal        + materials, sections, pads, modal (without  mesh.h5
                              damping settings, ``modal.out_of_core``
                              and the band split), boundary
static.h5        modal        as modes.h5                                 mesh.h5, modes.h5
modal_damping.h5 modal        + pads, [damping]                           mesh.h5, modes.h5
mbs.h5           mbs          + damping settings, [damping], vehicle,     modes.h5
                              irregularity (and its file), mbs            (static.h5,
                                                                          modal_damping.h5)
fields.h5        reconstruct  + output.dt, window, float32,               modes.h5, mbs.h5
                              static_correction_rates                     (static.h5)
probes.h5        reconstruct  + output.window, probes,                    modes.h5, mbs.h5
                              static_correction_rates                     (static.h5)
assessment.json  assess       the whole case                              modes.h5, mbs.h5,
                                                                          fields.h5, probes.h5
result.json      study        the whole variant case, study, probes       modes.h5, mbs.h5,
                                                                          probes.h5 (static.h5)
                                                                          or transient.h5,
                                                                          probes.h5
===============  ===========  ==========================================  ===================

The full-order solution (``railvib transient``, its own folder, by default
``results/<name>/transient``) has its own rows. It writes ``fields.h5`` and ``probes.h5``
in the layout of ``reconstruct`` (``assess`` and the studies read them unchanged), but
they are other results with other inputs, so they have their own table names,
``transient:fields.h5`` and ``transient:probes.h5`` (:attr:`StageFile.file` is the file
name on disk). A file records its table name (``railvib_file``) and stage, so a
``fields.h5`` of one stage is foreign to the other: it is never reused for it and
``assess`` refuses it as the other's input. No ``[mbs]`` key enters: the full-order
solver has its own time step and contact loop (the contact settings are in
``[vehicle]``); of ``[modal]`` only the keys that change K, M and C do:

========================  ===========  ======================================  =============
table name (file)         written by   case keys (inputs)                      upstream files
========================  ===========  ======================================  =============
transient.h5              transient    mesh keys (as mesh.h5), materials,      mesh.h5
                                       sections, pads, boundary, damping,
                                       vehicle, irregularity (and its file),
                                       transient (without
                                       ``checkpoint_interval``),
                                       modal.lumped_mass, hex_formulation,
                                       fix_sleeper_rotations,
                                       fix_rail_rotations_at_pads,
                                       damping_ratio, output.dt (the
                                       automatic step divides it)
transient:fields.h5       transient    + output.window, float32                mesh.h5
(fields.h5)                            (``/stress`` records its own hash with
                                       output.stress_times)
transient:probes.h5       transient    + output.probes, probe_roles            mesh.h5
(probes.h5)
transient_checkpoint.h5   transient    the union of the three above (it        mesh.h5
                                       resumes all of them)
========================  ===========  ======================================  =============

The three products come from one time integration: they are reused only together, and
one stale or missing product recomputes all three. The checkpoint is resumed only when
it is current and sound by the same rules as a result, and the partial ``fields.h5``
(:func:`resume_path`) carries the same run id.

Provenance
----------
Every file records (HDF5 root attributes; a ``provenance`` object in JSON files):
``railvib_file`` (its table name), ``format_version``, ``stage``, ``inputs_sha256``
(:func:`inputs_hash` of its case keys), ``input_files_sha256`` (content of external
input files), ``upstream_sha256`` (content digests of the upstream files it read),
``railvib_version``, ``created`` (UTC) and ``case_toml`` (the merged case), plus
``complete = 1`` set last.

Content digests and records
---------------------------
A file's content digest (:func:`hash_file`) is a SHA-256 over fixed 64 MiB blocks: the
digest of block ``i`` is computed on rank ``i mod size`` and the block digests are
combined in order, so the result does not depend on the number of ranks. It is computed
after the file is closed and renamed and kept in a small record
``<out>/.railvib/<file>.json`` (size, mtime_ns, digest). Later, a file whose size and
modification time match its record is trusted without reading it; any other file is
hashed again: the same digest refreshes the record, another one means the file changed
after it was written (corrupt). A file without record (deleted ``.railvib``) is hashed
and fully data-checked.

Reuse (:func:`examine`)
-----------------------
A result is reused only when it exists with its companions, is complete, has the
current format, its inputs hash equals the current case's, the digests of the upstream
files it recorded equal the current files' digests (an upstream file that no longer
exists is not a contradiction: the inputs hash covers its case keys), its content is
unchanged since it was written, and its data checks pass (:mod:`.stage_checks`; only
the cheap ones when the content is vouched for by the record, because the full checks
ran when it was written). The verdict says why not, in one line, naming the changed case
keys (``materials.subgrade.E = 2e8, the case says 4e8``).

A stage recomputes its own stale output and says why; a stage whose *input* (the output
of an earlier stage) is stale or corrupt refuses with one line naming the file, what
differs and the command to run (:func:`require_inputs`).

Writes
------
Every file is written under :func:`temp_path`
(``.<name>.part-<host>-<pid>_t<thread>_<random>``, unique per writer, threads included),
checked (it exists, is not empty, re-reads; HDF5 files are created, reserved with
``fallocate`` for their predicted size and only then filled, so a full disk fails before
any data is written), flushed to disk (``fsync``), renamed and then recorded. Free space is checked
against the predicted size first. A stage deletes a stale result before recomputing it,
so an interrupted run never leaves a stale file that looks current.

Locks
-----
One lock per output folder (:func:`output_lock`): ``fcntl.flock`` on
``<out>/.railvib/lock``, held by rank 0 for the whole command and re-entrant within the
thread that took it; the holder writes its pid, host and command into the file. A second
command into the same folder -- another process, or another thread of this process (a
second :class:`~railvib_hpc.api.Pipeline` on the same folder) -- refuses at once naming
the holder, or waits with ``wait=True`` (``--wait``). Taking the lock removes the
temporary files of dead processes. (``flock`` works across the nodes of a cluster on
NFSv4 and Lustre; on file systems without distributed locks, concurrent jobs must use
different ``--out`` folders.)

API
---
* digests: :func:`digest` (JSON objects), :func:`hash_file` (collective), :func:`file_digest`
  (trusting a matching record), :func:`record_file`;
* the table: :data:`STAGE_FILES`, :func:`spec`, :func:`inputs_hash`, :func:`provenance`,
  :func:`case_differences`;
* reuse: :func:`examine` -> :class:`Verdict`, :func:`require_inputs` (raises
  :class:`~railvib_hpc.errors.StaleInputError`), :func:`forget`;
* writes: :func:`write_h5` (collective HDF5), :func:`start_h5` + :func:`commit_h5` (the
  same steps around a file filled over a long computation, e.g. under its
  :func:`resume_path`), :func:`write_json`, :func:`write_text`, :func:`atomic_file`,
  :func:`copy_file`, :func:`ensure_space`, :func:`reserve`, :func:`temp_path`;
* locks: :func:`output_lock` (collective context manager), :func:`acquire_lock`,
  :func:`release_lock`, :func:`holds_lock`, :func:`remove_stale_temps`.
"""

from __future__ import annotations

import contextlib
import ctypes
import datetime
import errno
import fcntl
import hashlib
import json
import math
import os
import re
import shutil
import socket
import threading
import uuid
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomllib

from .. import __version__
from ..errors import OutputError, OutputLockedError, StaleInputError, UserError, os_error_text

#: Folder of the records, the lock and crash logs inside an output folder.
RECORD_DIR = ".railvib"
#: Block size of the content digest (each block hashed on its own rank).
BLOCK_BYTES = 64 * 2**20
#: Free-space margin on top of a file's predicted size: HDF5 metadata, attributes
#: (the case TOML), companions; relative part and absolute part.
SPACE_MARGIN = (0.05, 8 * 2**20)
_DIGEST_TAG = b"railvib-sha256-blocks/1\0"


# ----------------------------------------------------------------------------- digests
def digest(obj: Any) -> str:
    """SHA-256 of a JSON-serialisable object (canonical: sorted keys, ``str`` for others).

    Examples
    --------
    >>> digest({"b": 1, "a": [1.0, "x"]}) == digest({"a": [1.0, "x"], "b": 1})
    True
    """
    text = json.dumps(obj, sort_keys=True, default=str, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def _hash_blocks(path: Path, blocks: Iterable[int]) -> dict[int, bytes]:
    out = {}
    with open(path, "rb") as f:
        for i in blocks:
            f.seek(i * BLOCK_BYTES)
            h = hashlib.sha256()
            left = BLOCK_BYTES
            while left:
                chunk = f.read(min(left, 8 * 2**20))
                if not chunk:
                    break
                h.update(chunk)
                left -= len(chunk)
            out[i] = h.digest()
    return out


def hash_file(path: str | os.PathLike, comm=None) -> str:
    """Content digest of a file: SHA-256 over its 64 MiB blocks (collective with ``comm``).

    Block ``i`` is hashed on rank ``i mod size``; the block digests are combined in
    order with the file size, so the digest is the same for any number of ranks.
    """
    from ..parallel import check_collective

    path = Path(path)
    size = comm.size if comm is not None else 1
    rank = comm.rank if comm is not None else 0
    nbytes, error = 0, None
    try:
        nbytes = os.stat(path).st_size
    except OSError as exc:
        error = exc
    if comm is not None:
        check_collective(comm, error, f"reading {path}")
        nbytes = comm.bcast(nbytes, root=0)
    elif error is not None:
        raise error
    n_blocks = max(1, math.ceil(nbytes / BLOCK_BYTES))
    parts: dict[int, bytes] = {}
    try:
        parts = _hash_blocks(path, range(rank, n_blocks, size))
    except OSError as exc:
        error = exc
    if comm is not None and size > 1:
        check_collective(comm, error, f"reading {path}")
        for p in comm.allgather(parts):
            parts.update(p)
    elif error is not None:
        raise error
    h = hashlib.sha256(_DIGEST_TAG + nbytes.to_bytes(8, "little"))
    for i in range(n_blocks):
        h.update(parts[i])
    return h.hexdigest()


def record_path(path: Path) -> Path:
    """The record of ``path``: ``<folder>/.railvib/<name>.json``."""
    return path.parent / RECORD_DIR / f"{path.name}.json"


def read_record(path: Path) -> dict | None:
    """The record of ``path`` (None when missing or unreadable)."""
    try:
        rec = json.loads(record_path(path).read_text())
    except (OSError, ValueError):
        return None
    return rec if isinstance(rec, dict) else None


def write_record(path: Path, sha: str) -> None:
    """Record the size, modification time and content digest of ``path`` (rank 0)."""
    st = os.stat(path)
    rec = {"file": path.name, "size": st.st_size, "mtime_ns": st.st_mtime_ns, "sha256": sha,
           "block_bytes": BLOCK_BYTES, "recorded": _now()}
    rp = record_path(path)
    rp.parent.mkdir(exist_ok=True)
    _write_bytes_atomic(rp, json.dumps(rec, indent=1).encode())


def forget(path: Path) -> None:
    """Delete a result file and its record (before it is recomputed; rank 0)."""
    for p in (path, record_path(path)):
        if p.is_symlink() or p.exists():
            p.unlink()


@dataclass(frozen=True)
class FileDigest:
    """Content digest of a file and how it was obtained.

    ``status``: ``recorded`` (the record matches, or the file was hashed and equals it),
    ``unrecorded`` (no record: hashed now) or ``changed`` (hashed now, differs from the
    record written with the file: it was modified afterwards).
    """

    sha256: str
    status: str


def file_digest(path: str | os.PathLike, comm=None) -> FileDigest:
    """Digest of ``path`` (symlinks resolved), trusting a record whose size and mtime match.

    Collective when ``comm`` is given (only hashing needs every rank); serial otherwise.
    """
    real = Path(os.path.realpath(path))
    rank0 = comm is None or comm.rank == 0
    rec = read_record(real) if rank0 else None
    trusted = None
    if rank0:
        st = os.stat(real)
        if (rec is not None and rec.get("size") == st.st_size
                and rec.get("mtime_ns") == st.st_mtime_ns
                and rec.get("block_bytes") == BLOCK_BYTES and rec.get("sha256")):
            trusted = str(rec["sha256"])
    if comm is not None and comm.size > 1:
        trusted = comm.bcast(trusted, root=0)
    if trusted is not None:
        return FileDigest(trusted, "recorded")
    sha = hash_file(real, comm)
    if not rank0:
        return FileDigest(sha, "unrecorded")
    if rec is None:
        return FileDigest(sha, "unrecorded")
    if rec.get("sha256") == sha:
        with contextlib.suppress(OSError):           # e.g. copied: refresh size/mtime
            write_record(real, sha)
        return FileDigest(sha, "recorded")
    return FileDigest(sha, "changed")


def record_file(path: Path, comm=None) -> str:
    """Hash ``path`` (collective with ``comm``) and write its record (rank 0); returns it."""
    sha = hash_file(path, comm)
    if comm is None or comm.rank == 0:
        write_record(path, sha)
    return sha


# ----------------------------------------------------------------------------- the table
#: A selection of case keys: (dotted prefix, leaf names left out below it).
Selection = tuple[tuple[str, tuple[str, ...]], ...]

#: The mesh: its geometry and divisions, the soil layers, the elastic interfaces (they cut
#: the mesh), and the soils' E, nu, rho (the wavelength sizing, mesh.elements_per_wavelength,
#: reads their shear-wave speeds).
_SOIL_WAVE_SPEED = ("damping_ratio",)
_MESH = (("geometry", ()), ("track", ()), ("building", ()), ("mesh", ()), ("domain", ()),
         ("soil", ()), ("trench", ()), ("wib", ()), ("usp", ()), ("ballast_mat", ()),
         ("isolation", ()), ("materials.ballast", _SOIL_WAVE_SPEED),
         ("materials.subballast", _SOIL_WAVE_SPEED), ("materials.subgrade", _SOIL_WAVE_SPEED))
#: How the modes are computed, not what they are: the out-of-core switch and the band
#: split with its parallel layout (they change the modes by round-off only).
MODAL_SOLVER_LAYOUT = ("out_of_core", "bands", "band_modes", "band_groups", "band_only")
#: The damping settings of [modal] and [pads] (and the materials' ratios): not the modes.
MODAL_DAMPING_KEYS = ("damping_ratio", "damping")
#: Damping settings and the solver layout do not change the modes.
MODAL_ONLY_EXCLUDED = (*MODAL_DAMPING_KEYS, *MODAL_SOLVER_LAYOUT)
#: A band of the band-sliced solve (its cache in ``<out>/bands``) depends on [modal] as the
#: modes do, except on how many modes up to which frequency are wanted and on the basis
#: and shift of an unsliced solve (:func:`railvib_hpc.modal.band_solve.cache_key`).
BAND_EXTENT = ("f_max", "n_modes", "max_basis", "shift_hz")
_MODAL = _MESH + (("materials", MODAL_ONLY_EXCLUDED), ("sections", ()),
                  ("pads", MODAL_ONLY_EXCLUDED), ("modal", MODAL_ONLY_EXCLUDED),
                  ("boundary", ()))
#: The projected parts of C (``modal.damping = 'full'``): the modes' inputs, the pads'
#: dashpots and [damping] (the ratios only enter when composed, but the whole section is
#: kept for safety). Whether the static fields are projected too is in the file's shape:
#: one with them serves a run without the static correction as well.
_MODAL_DAMPING = _MODAL + (("pads", ()), ("damping", ()))
_MBS = _MESH + (("materials", ()), ("sections", ()), ("pads", ()),
                ("modal", MODAL_SOLVER_LAYOUT), ("boundary", ()), ("damping", ()),
                ("vehicle", ()), ("train2", ()), ("irregularity", ()), ("mbs", ()))
_FIELDS = _MBS + (("output.dt", ()), ("output.window", ()), ("output.float32", ()),
                  ("output.static_correction_rates", ()))
_PROBES = _MBS + (("output.window", ()), ("output.probes", ()),
                  ("output.static_correction_rates", ()))
_ALL: Selection = (("", ()),)


@dataclass(frozen=True)
class StageFile:
    """One row of :data:`STAGE_FILES`.

    Attributes
    ----------
    name
        File name in the output folder.
    stage
        The command that writes it (``railvib <stage>``).
    version
        Format version: bumped when the layout or the meaning of the file changes; a
        file of another version is recomputed (or refused as an input).
    inputs
        The case keys it depends on (cumulative over its upstream files).
    upstream
        The files it is computed from (those in parentheses in the module table are read
        only with the static correction).
    companions
        Files written with it that must exist for it to be reused (XDMF, reports).
    input_files
        Case keys naming external files whose content is part of the inputs.
    """

    name: str
    stage: str
    version: int
    inputs: Selection
    upstream: tuple[str, ...] = ()
    companions: tuple[str, ...] = ()
    input_files: tuple[str, ...] = ()
    file: str = ""

    @property
    def filename(self) -> str:
        """The file name in the output folder (``file``, or the table name)."""
        return self.file or self.name


#: The full-order solution (``railvib transient``): everything that changes K, M, C, the
#: loads and the time step; ``transient.checkpoint_interval`` is how it runs, not what.
_TRANSIENT = _MESH + (("materials", ()), ("sections", ()), ("pads", ()), ("boundary", ()),
                      ("damping", ()), ("vehicle", ()), ("train2", ()), ("irregularity", ()),
                      ("transient", ("checkpoint_interval",)), ("modal.lumped_mass", ()),
                      ("modal.hex_formulation", ()), ("modal.fix_sleeper_rotations", ()),
                      ("modal.fix_rail_rotations_at_pads", ()), ("modal.damping_ratio", ()),
                      ("output.dt", ()))
_TRANSIENT_FIELDS = _TRANSIENT + (("output.window", ()), ("output.float32", ()))
_TRANSIENT_PROBES = _TRANSIENT + (("output.probes", ()), ("output.probe_roles", ()))
_TRANSIENT_STATE = _TRANSIENT_FIELDS + (("output.probes", ()), ("output.probe_roles", ()))
_FILES = ("mesh.file", "irregularity.file")


STAGE_FILES: dict[str, StageFile] = {f.name: f for f in (
    StageFile("mesh.h5", "mesh", 2, _MESH, (), ("mesh.xdmf", "mesh_report.json"),
              ("mesh.file",)),
    StageFile("modes.h5", "modal", 2, _MODAL, ("mesh.h5",), ("modes.xdmf",), ("mesh.file",)),
    StageFile("static.h5", "modal", 2, _MODAL, ("mesh.h5", "modes.h5"), (), ("mesh.file",)),
    StageFile("modal_damping.h5", "modal", 2, _MODAL_DAMPING, ("mesh.h5", "modes.h5"), (),
              ("mesh.file",)),
    StageFile("mbs.h5", "mbs", 2, _MBS, ("modes.h5", "static.h5", "modal_damping.h5"), (),
              ("mesh.file", "irregularity.file")),
    StageFile("fields.h5", "reconstruct", 2, _FIELDS, ("modes.h5", "mbs.h5", "static.h5"),
              ("fields.xdmf",), ("mesh.file", "irregularity.file")),
    StageFile("probes.h5", "reconstruct", 2, _PROBES, ("modes.h5", "mbs.h5", "static.h5"),
              (), ("mesh.file", "irregularity.file")),
    StageFile("assessment.json", "assess", 2, _ALL,
              ("modes.h5", "static.h5", "mbs.h5", "fields.h5", "probes.h5"),
              ("report.md", "report.html", "report.json"), ("mesh.file", "irregularity.file")),
    StageFile("result.json", "study", 2, _ALL, ("modes.h5", "static.h5", "mbs.h5", "probes.h5",
                                                  "transient.h5"),
              (), ("mesh.file", "irregularity.file")),
    StageFile("transient.h5", "transient", 2, _TRANSIENT, ("mesh.h5",), (), _FILES),
    StageFile("transient:fields.h5", "transient", 2, _TRANSIENT_FIELDS, ("mesh.h5",),
              ("fields.xdmf",), _FILES, file="fields.h5"),
    StageFile("transient:probes.h5", "transient", 2, _TRANSIENT_PROBES, ("mesh.h5",), (),
              _FILES, file="probes.h5"),
    StageFile("transient_checkpoint.h5", "transient", 2, _TRANSIENT_STATE, ("mesh.h5",), (),
              _FILES),
)}


def spec(name: str) -> StageFile:
    """The table row of ``name`` (a file name, e.g. ``modes.h5``)."""
    try:
        return STAGE_FILES[name]
    except KeyError:
        raise KeyError(f"{name} is not a stage file; known: {', '.join(STAGE_FILES)}") \
            from None


def whole_sections(name: str) -> tuple[str, ...]:
    """The case sections stage file ``name`` depends on whole (no key left out below them),
    in table order.

    Examples
    --------
    >>> whole_sections("mesh.h5")[:4]
    ('geometry', 'track', 'building', 'mesh')
    """
    return tuple(k for k, left_out in spec(name).inputs if k and "." not in k and not left_out)


def flat_case(data: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested case data as ``{dotted key: value}``."""
    out: dict[str, Any] = {}
    for k, v in data.items():
        key = f"{prefix}{k}"
        if isinstance(v, Mapping):
            out.update(flat_case(v, key + "."))
        else:
            out[key] = v
    return out


def select(flat: Mapping[str, Any], selection: Selection) -> dict[str, Any]:
    """The entries of a flat case that a selection names."""
    out = {}
    for key, value in flat.items():
        leaf = key.rsplit(".", 1)[-1]
        for prefix, excluded in selection:
            if (not prefix or key == prefix or key.startswith(prefix + ".")) \
                    and leaf not in excluded:
                out[key] = value
                break
    return out


def _external_files(case, keys: Sequence[str]) -> dict[str, str]:
    """Content digests of the external input files named by ``keys`` (when in use)."""
    out = {}
    for key in keys:
        if key == "irregularity.file" and case["irregularity.type"] != "file":
            continue
        if case[key]:
            out[key] = hash_file(case.resolve(case[key]))
    return out


def inputs_hash(case, name: str, extra: Any = None) -> str:
    """SHA-256 of the case keys (and external files) that ``name`` depends on."""
    s = spec(name)
    return digest({"keys": select(flat_case(case.data), s.inputs),
                   "files": _external_files(case, s.input_files), "extra": extra})


def provenance(name: str, case, upstream: Mapping[str, str], extra: Any = None,
               inputs_sha256: str | None = None) -> dict[str, Any]:
    """The provenance attributes of a new ``name`` (``complete`` is set by the writer).

    Parameters
    ----------
    name
        Table name of the file.
    case
        The case it is computed for (None: a file computed outside a case, e.g. by a
        library call; then ``inputs_sha256`` must be given).
    upstream
        ``{file name: content digest}`` of the files it was computed from.
    extra
        Anything else its inputs hash must cover (e.g. options not in the case).
    inputs_sha256
        Overrides the inputs hash.
    """
    s = spec(name)
    files = _external_files(case, s.input_files) if case is not None else {}
    return {
        "railvib_file": name, "format_version": s.version, "stage": s.stage,
        "inputs_sha256": inputs_sha256 or inputs_hash(case, name, extra),
        "input_files_sha256": json.dumps(files, sort_keys=True),
        "upstream_sha256": json.dumps(dict(upstream), sort_keys=True),
        "railvib_version": __version__, "created": _now(),
        "case_toml": case.to_toml() if case is not None else "",
    }


def read_provenance(path: Path) -> dict[str, Any]:
    """Provenance (and ``complete``) of an HDF5 or JSON stage file.

    Raises
    ------
    OSError, ValueError, KeyError
        When the file cannot be read as a stage file.
    """
    if path.suffix == ".json":
        doc = json.loads(path.read_text())
        prov = dict(doc.get("provenance") or {})
        prov["complete"] = 1 if doc.get("complete") is True else 0
        return prov
    import h5py

    with h5py.File(path, "r") as f:
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}


def _fmt(value: Any) -> str:
    if value is None:
        return "(not set)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        text = f"{value:g}"
        return re.sub(r"e\+?(-?)0*(\d)", r"e\1\2", text)
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, str):
        return repr(value)
    return str(value)


def case_differences(name: str, stored_toml: str, case, stored_files: str = "{}",
                     limit: int = 3) -> str:
    """What differs between the case a file was computed with and the current case.

    Returns
    -------
    str
        E.g. ``materials.subgrade.E = 2e8, the case says 4e8``; several keys are joined
        with ``;`` (the first ``limit``, then ``(+k more)``); an empty string when nothing
        in the file's keys differs.

    Raises
    ------
    ValueError
        When the stored case is missing or not readable.
    """
    s = spec(name)
    if not stored_toml:
        raise ValueError("no case recorded")
    try:
        old = select(flat_case(tomllib.loads(stored_toml)), s.inputs)
    except (tomllib.TOMLDecodeError, TypeError) as exc:
        raise ValueError(f"the recorded case is not readable ({exc})") from None
    new = select(flat_case(case.data), s.inputs)
    diffs = [f"{k} = {_fmt(old.get(k))}, the case says {_fmt(new.get(k))}"
             for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
    try:
        files_old = json.loads(stored_files or "{}")
    except ValueError:
        files_old = {}
    files_new = _external_files(case, s.input_files)
    diffs += [f"the content of {k} ({case[k]}) changed" for k in sorted(set(files_old)
              | set(files_new)) if files_old.get(k) != files_new.get(k)
              and old.get(k) == new.get(k)]
    if len(diffs) > limit:
        diffs = diffs[:limit] + [f"(+{len(diffs) - limit} more)"]
    return "; ".join(diffs)


# ----------------------------------------------------------------------------- verdicts
@dataclass
class Verdict:
    """Whether a stage file can be used, and if not, why (one line).

    Attributes
    ----------
    ok
        True: reuse it.
    reason
        Why not, e.g. ``it was computed with vehicle.speed = 30, the case says 20``.
    kind
        ``missing``, ``incomplete``, ``format``, ``foreign``, ``inputs``, ``upstream``,
        ``corrupt`` or ``ok``.
    sha256
        Its content digest (when known).
    attrs
        Its provenance attributes (when readable).
    """

    ok: bool
    reason: str = ""
    kind: str = "ok"
    sha256: str = ""
    attrs: dict = field(default_factory=dict)


DataCheck = Callable[[Path, bool, Mapping[str, Any]], Sequence[str]]


def examine(path: str | os.PathLike, name: str | None = None, case=None, *,
            inputs_sha256: str | None = None, extra: Any = None,
            data_check: DataCheck | None = None, context: Mapping[str, Any] | None = None,
            companions: bool = True, upstream_dir: Path | None = None,
            upstream: Mapping[str, str] | None = None) -> Verdict:
    """Decide whether a stage file is current and sound (rank 0, serial).

    Parameters
    ----------
    path
        The file.
    name
        Its table name (default: the file name).
    case
        The current case (its inputs hash is compared); None to skip that comparison.
    inputs_sha256
        The expected inputs hash (default: :func:`inputs_hash` of ``case``).
    extra
        Extra inputs, as given to :func:`provenance`.
    data_check
        ``check(path, full, context) -> problems``; ``full`` is False when the content
        is vouched for by its record (the full checks ran when it was written).
    context
        Passed to ``data_check`` (e.g. the case, the modes file).
    companions
        Require the table's companion files.
    upstream_dir
        Folder of the upstream files (default: the file's folder).
    upstream
        The expected ``{name: content digest}`` of its upstream files (a stage checking its
        own output knows them); default: compare the recorded digests with the files now
        in ``upstream_dir`` (a file that no longer exists is no contradiction: its case
        keys are in the inputs hash).
    """
    path = Path(path)
    name = name or path.name
    s = spec(name)
    if not path.exists():
        return Verdict(False, "it does not exist", "missing")
    try:
        attrs = read_provenance(path)
    except (OSError, ValueError, KeyError, UnicodeDecodeError) as exc:
        return Verdict(False, f"it cannot be read ({_short(exc)})", "corrupt")
    if int(attrs.get("complete", 0) or 0) != 1:
        return Verdict(False, "it is incomplete (an interrupted write)", "incomplete", "", attrs)
    if attrs.get("railvib_file") not in (None, name) or attrs.get("stage") not in (None, s.stage):
        other = attrs.get("stage")
        if other and other != s.stage and attrs.get("railvib_file") in (name, s.filename,
                                                                        f"{other}:{s.filename}"):
            return Verdict(False, f"it was written by 'railvib {other}', not by 'railvib "
                           f"{s.stage}'", "foreign", "", attrs)
        return Verdict(False, f"it is not a railvib {name} (it says "
                       f"{attrs.get('railvib_file')})", "foreign", "", attrs)
    version = attrs.get("format_version")
    if version != s.version:
        return Verdict(False, f"it has format {version if version is not None else 1}, this "
                       f"railvib ({__version__}) writes format {s.version}", "format", "", attrs)
    if inputs_sha256 is not None or (case is not None and extra is not None):
        expected = inputs_sha256 or inputs_hash(case, name, extra)
        if attrs.get("inputs_sha256") != expected:
            diff = ""
            if case is not None:
                with contextlib.suppress(ValueError):
                    diff = case_differences(name, str(attrs.get("case_toml", "")), case,
                                            str(attrs.get("input_files_sha256", "{}")))
            return Verdict(False, f"it was computed with {diff}" if diff else
                           "it was computed for other inputs or options", "inputs", "", attrs)
    elif case is not None:
        try:
            diff = case_differences(name, str(attrs.get("case_toml", "")), case,
                                    str(attrs.get("input_files_sha256", "{}")))
        except ValueError:
            return Verdict(False, "it records no readable case", "inputs", "", attrs)
        if diff:
            return Verdict(False, f"it was computed with {diff}", "inputs", "", attrs)
    try:
        recorded = json.loads(str(attrs.get("upstream_sha256", "{}")) or "{}")
    except ValueError:
        return Verdict(False, "it has an unreadable provenance", "corrupt", "", attrs)
    if upstream is not None:
        differ = sorted(k for k in set(recorded) | set(upstream)
                        if recorded.get(k) != upstream.get(k))
        if differ:
            return Verdict(False, f"it was computed from another {differ[0]}", "upstream", "",
                           attrs)
        recorded = {}
    folder = upstream_dir or path.parent
    for up_name, up_sha in recorded.items():
        up = folder / up_name
        if not up.exists():
            continue                    # removed later: its case keys are in our inputs hash
        try:
            current = file_digest(up).sha256
        except OSError as exc:
            return Verdict(False, f"it was computed from {up_name}, which cannot be read "
                           f"now ({_short(exc)})", "upstream", "", attrs)
        if current != up_sha:
            return Verdict(False, f"it was computed from another {up_name} ({up_name} was "
                           "written again since)", "upstream", "", attrs)
    if companions:
        missing = [c for c in s.companions if not (path.parent / c).exists()]
        if missing:
            return Verdict(False, f"it lacks {', '.join(missing)}, written with it",
                           "incomplete", "", attrs)
    try:
        fd = file_digest(path)
    except OSError as exc:
        return Verdict(False, f"it cannot be read ({_short(exc)})", "corrupt", "", attrs)
    if fd.status == "changed":
        return Verdict(False, "it is corrupt (its content changed after it was written)",
                       "corrupt", fd.sha256, attrs)
    if data_check is not None:
        try:
            problems = list(data_check(path, fd.status != "recorded", dict(context or {})))
        except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
            problems = [f"it cannot be read ({_short(exc)})"]
        if problems:
            return Verdict(False, f"it is corrupt ({'; '.join(problems[:3])})", "corrupt",
                           fd.sha256, attrs)
    return Verdict(True, "", "ok", fd.sha256, attrs)


def _short(exc: BaseException) -> str:
    if isinstance(exc, OSError):
        return os_error_text(exc)
    text = (str(exc).splitlines() or [""])[0]
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


def rerun_hint(name: str) -> str:
    """``run 'railvib modal' (or 'railvib run')`` for the command that writes ``name``
    (``run 'railvib transient'`` for the full-order solution: not part of ``run``)."""
    stage = spec(name).stage
    if stage == "study":
        return "rerun the study"
    if stage == "transient":
        return "run 'railvib transient'"
    return f"run 'railvib {stage}' (or 'railvib run')"


def refuse(path: Path, verdict: Verdict, name: str | None = None) -> StaleInputError:
    """The one-line error of a single-stage command whose input ``path`` (table name
    ``name``, default its file name) is unusable."""
    name = name or (spec(path.name).name if path.name in STAGE_FILES else path.name)
    if verdict.kind == "missing":
        if name in STAGE_FILES and spec(name).stage == "transient":
            return StaleInputError(f"{path} not found: run 'railvib transient' first")
        stage = spec(name).stage if name in STAGE_FILES else "run"
        return StaleInputError(f"{path} not found: run 'railvib {stage}' first (or 'railvib "
                               "run')")
    reason = verdict.reason
    text = f"{path} {reason[3:]}" if reason.startswith("it ") else f"{path}: {reason}"
    return StaleInputError(f"{text}: {rerun_hint(name)}")


def require_inputs(out_dir: Path, names: Sequence[str], case, checks: Mapping[str, Any]
                   | None = None, context: Mapping[str, Any] | None = None
                   ) -> dict[str, Verdict]:
    """Verify the input files of a stage, in pipeline order (rank 0).

    Parameters
    ----------
    out_dir
        Output folder holding them.
    names
        Their table names, upstream first (e.g. ``("modes.h5", "mbs.h5")``); each is looked
        for under its file name (:attr:`StageFile.filename`).
    case
        The current case (None: compare no inputs hash).
    checks
        ``{name: data check}`` (see :func:`examine`).
    context
        Passed to the data checks.

    Returns
    -------
    dict
        The verdicts (all ok), with the content digests.

    Raises
    ------
    StaleInputError
        For the first file (in pipeline order) that is missing, stale, foreign or
        corrupt: one line naming it, what differs and the command to run.
    """
    out = {}
    for name in names:
        path = out_dir / spec(name).filename
        v = examine(path, name, case, data_check=(checks or {}).get(name), context=context,
                    companions=False)
        if not v.ok:
            raise refuse(path, v, name)
        out[name] = v
    return out


# ----------------------------------------------------------------------------- writes
def _host() -> str:
    return re.sub(r"[^A-Za-z0-9.-]", "_", socket.gethostname()) or "host"


def temp_path(path: str | os.PathLike, suffix: bool = False) -> Path:
    """The temporary name of ``path`` while it is written:
    ``.<name>.part-<host>-<pid>_t<thread>_<random>`` (with ``suffix``, the file's extension
    again at the end, for writers such as gmsh that choose the format by it).

    Unique per writer: two threads of one process (two :class:`~railvib_hpc.api.Pipeline`
    objects), or two writes of one thread, never share a temporary name. The pid stays in
    the name for :func:`remove_stale_temps`.
    """
    path = Path(path)
    token = f"{os.getpid()}_t{threading.get_native_id()}_{uuid.uuid4().hex[:12]}"
    return path.with_name(f".{path.name}.part-{_host()}-{token}"
                          + (path.suffix if suffix else ""))


def final_name(name: str) -> str:
    """The final file name of a temporary name of :func:`temp_path` (others unchanged)."""
    m = _TEMP_RE.match(name)
    if not m:
        if name.startswith(".") and name.endswith(_RESUME_SUFFIX):
            return name[1:-len(_RESUME_SUFFIX)]
        return name
    return name[1:name.rindex(".part-" if ".part-" in name else ".copy-")]


_RESUME_SUFFIX = ".resume"


def resume_path(path: str | os.PathLike) -> Path:
    """The temporary name of a result that is written over several runs: ``.<name>.resume``
    (a resumable run's partial file, e.g. the fields of an interrupted ``railvib
    transient``).

    Unlike :func:`temp_path` it names no process, and :func:`remove_stale_temps` leaves it:
    a later run continues it when the provenance it carries matches its checkpoint, and
    deletes it otherwise. Complete it with :func:`start_h5` ... :func:`commit_h5`.
    """
    path = Path(path)
    return path.with_name(f".{path.name}{_RESUME_SUFFIX}")


#: A temporary name of :func:`temp_path`: ``.<name>.part-<host>-<pid>[_t<tid>_<hex>][.ext]``
#: (the older ``.<name>.part-<host>-<pid>`` and ``.<name>.part-<pid>`` included).
_TEMP_RE = re.compile(r"^\..+\.(?:part|copy)-(?:(?P<host>.+)-)?(?P<pid>\d+)"
                      r"(?:_t\d+_[0-9a-f]+)?(?:\.[A-Za-z0-9]+)?$")
_OLD_GMSH_TEMP = re.compile(r"^.+\.part\.msh$")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale_temps(folder: Path) -> tuple[int, int]:
    """Delete temporary files of dead processes in ``folder`` and its direct subfolders.

    Call only while holding the folder's lock: a temporary file of another host, or of a
    process of this host that no longer runs, then belongs to an interrupted run.

    Returns
    -------
    tuple
        Number of files and bytes removed.
    """
    count, nbytes = 0, 0
    host = _host()
    dirs = [folder] + [d for d in folder.iterdir() if d.is_dir() and not d.is_symlink()
                       and d.name != RECORD_DIR]
    for d in dirs:
        for p in d.iterdir():
            m = _TEMP_RE.match(p.name)
            stale = False
            if m:
                same_host = m["host"] is None or m["host"] == host
                stale = not same_host or not _pid_alive(int(m["pid"]))
            elif _OLD_GMSH_TEMP.match(p.name):
                stale = True
            if stale and p.is_file():
                with contextlib.suppress(OSError):
                    size = p.stat().st_size
                    p.unlink()
                    count += 1
                    nbytes += size
    return count, nbytes


def _fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(folder: Path) -> None:
    with contextlib.suppress(OSError):           # not every file system allows it
        _fsync_path(folder)


def free_bytes(folder: Path) -> int:
    """Bytes available to this user in ``folder``'s file system."""
    st = os.statvfs(folder)
    return st.f_bavail * st.f_frsize


def needed_bytes(size_hint: int) -> int:
    """Predicted size plus the :data:`SPACE_MARGIN`."""
    return int(size_hint * (1.0 + SPACE_MARGIN[0])) + SPACE_MARGIN[1]


def ensure_space(folder: str | os.PathLike, size_hint: int, what: str) -> None:
    """Raise :class:`OutputError` when ``folder`` lacks room for ``size_hint`` bytes (+ margin).

    HDF5 can crash or hang on a full disk, so every big file is checked before it is
    created.
    """
    folder = Path(folder)
    need = needed_bytes(size_hint)
    free = free_bytes(folder)
    if free < need:
        raise OutputError(f"not enough free space in {folder} to write {what}: it needs "
                          f"{_size(need)} (predicted {_size(size_hint)} + margin), "
                          f"{_size(free)} are free; free some space or use another --out")


def _size(n: float) -> str:
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(n) < 1000 or unit == "TB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1000.0
    return f"{n:.1f} TB"


_FALLOC_FL_KEEP_SIZE = 1


def reserve(path: Path, nbytes: int) -> bool:
    """Reserve ``nbytes`` of disk for ``path`` without changing its size (Linux ``fallocate``
    with ``FALLOC_FL_KEEP_SIZE``), so later writes cannot fail for lack of space.

    Returns
    -------
    bool
        True when reserved, False when the file system does not support it.

    Raises
    ------
    OutputError
        When there is not enough space.
    """
    if nbytes <= 0 or not hasattr(os, "posix_fallocate"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        fallocate = libc.fallocate
    except (OSError, AttributeError):
        return False
    fallocate.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_int64, ctypes.c_int64]
    fd = os.open(path, os.O_RDWR)
    try:
        if fallocate(fd, _FALLOC_FL_KEEP_SIZE, 0, int(nbytes)) != 0:
            err = ctypes.get_errno()
            if err in (errno.ENOSPC, errno.EDQUOT, errno.EFBIG):
                raise OutputError(f"cannot reserve {_size(nbytes)} for {path.name} in "
                                  f"{path.parent}: {os.strerror(err)}; free some space or use "
                                  "another --out")
            return False                       # EOPNOTSUPP, EINVAL, ...: not supported
    finally:
        os.close(fd)
    return True


def _write_bytes_atomic(path: Path, data: bytes) -> None:
    tmp = temp_path(path)
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike, *, size_hint: int = 0,
                check: Callable[[Path], Sequence[str]] | None = None, record: bool = False,
                suffix: bool = False) -> Iterator[Path]:
    """Yield a temporary path for ``path``; on success check, fsync, rename (and record).

    Serial (one process). The temporary file is removed whatever happens; any
    ``OSError`` becomes :class:`OutputError` naming ``path``.

    Parameters
    ----------
    size_hint
        Predicted size: free space is checked before the block runs.
    check
        ``check(tmp) -> problems`` re-reads the written file (e.g. a truncated ``.msh``
        that ``gmsh.write`` did not report); any problem fails the write.
    record
        Record the content digest (stage files).
    suffix
        Keep the extension at the end of the temporary name (see :func:`temp_path`).
    """
    path = Path(path)
    tmp = temp_path(path, suffix)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if size_hint:
            ensure_space(path.parent, size_hint, path.name)
        yield tmp
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise OutputError(f"writing {path} failed: the written file is missing or empty "
                              "(disk full?)")
        _reread(check, tmp, path)
        _fsync_path(tmp)
        os.replace(tmp, path)
        _fsync_dir(path.parent)
        if record:
            write_record(path, hash_file(path))
    except OutputError:
        raise
    except OSError as exc:
        raise OutputError(f"writing {path}: {os_error_text(exc)}") from None
    finally:
        with contextlib.suppress(OSError):
            tmp.unlink()


def write_text(path: str | os.PathLike, text: str, record: bool = False) -> None:
    """Write a text file atomically (temporary name, fsync, rename)."""
    data = text.encode()
    with atomic_file(path, size_hint=len(data)) as tmp:
        tmp.write_bytes(data)
    if record:
        write_record(Path(path), hash_file(path))


def write_json(path: str | os.PathLike, doc: Mapping[str, Any], prov: Mapping[str, Any]
               | None = None) -> str:
    """Write a JSON stage file atomically with its provenance and ``complete = true`` last;
    record it. Returns its content digest."""
    body = dict(doc)
    if prov is not None:
        body["provenance"] = dict(prov)
    body["complete"] = True
    write_text(path, json.dumps(body, indent=1, default=_json_default))
    return record_file(Path(path))


def _json_default(x: Any) -> Any:
    try:
        import numpy as np

        if isinstance(x, np.generic):
            return x.item()
        if isinstance(x, np.ndarray):
            return x.tolist()
    except ImportError:  # pragma: no cover
        pass
    return float(x)


def _reread(check: Callable[[Path], Sequence[str]] | None, tmp: Path, path: Path) -> None:
    """Run a re-read check on a just-written temporary file; raise when it fails."""
    if check is None:
        return
    try:
        problems = list(check(tmp))
    except (OSError, ValueError, KeyError, IndexError, TypeError) as exc:
        problems = [f"it cannot be read back ({_short(exc)})"]
    if problems:
        raise OutputError(f"writing {path} failed: {problems[0]} (disk full or a bad file "
                          "system?)")


def _sync_h5(comm, error: BaseException | None, what: str, folder: Path) -> None:
    """Raise ``error`` of any rank on every rank (an ``OSError`` as :class:`OutputError`)."""
    from ..parallel import check_collective

    if isinstance(error, OSError) and not error.errno and not isinstance(error, UserError):
        with contextlib.suppress(OSError):        # MPI-IO reports no errno: name the cause
            if free_bytes(folder) < SPACE_MARGIN[1]:
                error = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    if comm is not None:
        check_collective(comm, error, what)
    elif error is not None:
        if isinstance(error, OSError) and not isinstance(error, UserError):
            raise OutputError(f"{what}: {os_error_text(error)}") from None
        raise error


def _sync_or_remove(comm, error: BaseException | None, what: str, folder: Path,
                    tmp: Path) -> None:
    """:func:`_sync_h5`, removing the temporary file ``tmp`` when any rank failed."""
    try:
        _sync_h5(comm, error, what, folder)
    except BaseException:
        _remove(comm, tmp)
        raise


def _remove(comm, tmp: Path) -> None:
    if comm is None or comm.rank == 0:
        with contextlib.suppress(OSError):
            tmp.unlink()


def start_h5(tmp: str | os.PathLike, comm, *, size_hint: int, what: str) -> None:
    """Create the temporary HDF5 file ``tmp`` of a stage file (collective over ``comm``).

    Rank 0 checks the free space for ``size_hint`` bytes (plus margin), creates the file
    with ``complete = 0`` and reserves the space, so that the data writes that follow
    cannot hit a full disk. The caller then opens it (``r+``, every rank with ``mpio`` or
    rank 0) and fills it; :func:`commit_h5` completes it. An error on any rank raises on
    every rank and removes the file. ``what`` names the final file in the messages.
    """
    import h5py

    tmp = Path(tmp)
    error = None
    if comm is None or comm.rank == 0:
        try:
            tmp.parent.mkdir(parents=True, exist_ok=True)
            ensure_space(tmp.parent, size_hint, what)
            with h5py.File(tmp, "w") as f:
                f.attrs["complete"] = 0
            reserve(tmp, needed_bytes(size_hint))
        except BaseException as exc:
            error = exc
    _sync_or_remove(comm, error, f"writing {tmp.parent / what}", tmp.parent, tmp)


def commit_h5(tmp: str | os.PathLike, path: str | os.PathLike, comm, *,
              check: Callable[[Path], Sequence[str]] | None = None,
              record: bool = True) -> str:
    """Complete a filled temporary HDF5 file and make it ``path`` (collective over ``comm``).

    Rank 0 sets ``complete = 1``, runs ``check(tmp)`` (re-read), fsyncs and renames; the
    content digest is computed on every rank and recorded. Call it after every rank closed
    the file. An error on any rank raises on every rank, and the temporary file is
    removed.

    Returns
    -------
    str
        The content digest of ``path`` ("" with ``record=False``).
    """
    import h5py

    tmp, path = Path(tmp), Path(path)
    error = None
    if comm is None or comm.rank == 0:
        try:
            with h5py.File(tmp, "r+") as f:
                f.attrs["complete"] = 1
            _reread(check, tmp, path)
            _fsync_path(tmp)
            os.replace(tmp, path)
            _fsync_dir(path.parent)
        except BaseException as exc:
            error = exc
    _sync_or_remove(comm, error, f"writing {path}", path.parent, tmp)
    if not record:
        return ""
    return record_file(path, comm)


def write_h5(path: str | os.PathLike, comm, fill: Callable[[Any, bool], None], *,
             size_hint: int, attrs: Mapping[str, Any] | None = None,
             parallel: bool | None = None,
             before_complete: Callable[[Path], None] | None = None,
             check: Callable[[Path], Sequence[str]] | None = None, record: bool = True,
             fill_everywhere: bool = False) -> str:
    """Write an HDF5 stage file atomically; collective over ``comm`` (None: serial).

    Steps: free space checked (rank 0); the file is created under its temporary name
    and ``size_hint`` bytes reserved (so data writes cannot hit a full disk; :func:`start_h5`);
    it is opened on every rank with the ``mpio`` driver (``parallel``) or on rank 0, the
    provenance ``attrs`` and ``complete = 0`` are written and ``fill(file, parallel)``
    writes the data; ``before_complete(tmp)`` may add more (collective); rank 0 sets
    ``complete = 1``, runs ``check(tmp)`` (re-read), fsyncs and renames; the content
    digest is computed on every rank and recorded (:func:`commit_h5`). An error on any
    rank raises on every rank (``OSError`` as :class:`OutputError`), and no file is left
    behind.

    ``fill_everywhere``: call ``fill(None, False)`` on the ranks that do not open the
    file (without parallel HDF5 they send their data to rank 0 inside ``fill``).

    Returns
    -------
    str
        The content digest of the new file.
    """
    import h5py

    from .parallel_h5 import h5py_parallel_ok

    path = Path(path)
    rank = comm.rank if comm is not None else 0
    if parallel is None:
        parallel = comm is not None and h5py_parallel_ok(comm)
    tmp = temp_path(path)
    if comm is not None and comm.size > 1:
        tmp = Path(comm.bcast(str(tmp) if rank == 0 else None, root=0))
    if comm is not None and comm.size > 1:
        attrs = comm.bcast(dict(attrs or {}) if rank == 0 else None, root=0)
    start_h5(tmp, comm, size_hint=size_hint, what=path.name)
    try:
        error = None
        try:
            if parallel or rank == 0:
                kw = {"driver": "mpio", "comm": comm} if parallel else {}
                with h5py.File(tmp, "r+", **kw) as f:
                    for k, v in (attrs or {}).items():
                        f.attrs[k] = v
                    f.attrs["complete"] = 0
                    fill(f, bool(parallel))
            elif fill_everywhere:
                fill(None, False)
        except BaseException as exc:
            error = exc
        _sync_h5(comm, error, f"writing {path}", path.parent)
        if before_complete is not None:
            before_complete(tmp)
    except BaseException:
        _remove(comm, tmp)
        raise
    return commit_h5(tmp, path, comm, check=check, record=record)


# ----------------------------------------------------------------------------- locks
#: The folder locks this process holds: ``{realpath: [fd, depth, thread ident, holder]}``
#: (fd None while the owning thread is still taking the file lock; holder: who, in
#: words). Guarded by :data:`_HELD_COND`.
_HELD: dict[str, list] = {}
#: Guards :data:`_HELD`; threads waiting for a folder held by another thread wait on it.
_HELD_COND = threading.Condition()


def _holder_text(lock: Path) -> str:
    try:
        info = json.loads(lock.read_text() or "{}")
    except (OSError, ValueError):
        info = {}
    if not info:
        return "another railvib process"
    return (f"pid {info.get('pid')} on {info.get('host')} ('{info.get('command')}', since "
            f"{info.get('started')})")


def _locked_error(out_dir: Path, holder: str) -> OutputLockedError:
    return OutputLockedError(f"the output folder {out_dir} is in use by {holder}; wait for "
                             "it to finish, use another --out, or add --wait")


def _claim(key: str, out_dir: Path, command: str, wait: bool,
           notify: Callable[[str], None] | None) -> bool:
    """Claim ``key`` for this thread in :data:`_HELD`: True when this thread already holds
    it (one level more), False when it is newly claimed (the file lock is still to take).
    Another thread of this process holding it refuses like another process, or waits."""
    me = threading.get_ident()
    with _HELD_COND:
        held = _HELD.get(key)
        if held is not None and held[2] == me:
            held[1] += 1
            return True
        if held is not None:
            holder = held[3]
            if not wait:
                raise _locked_error(out_dir, holder)
            if notify is not None:
                notify(f"waiting for the output folder {out_dir}, in use by {holder}")
            _HELD_COND.wait_for(lambda: key not in _HELD)
        _HELD[key] = [None, 1, me, f"thread {threading.get_native_id()} of this process "
                      f"(pid {os.getpid()}, '{command}', since {_now()})"]
        return False


def _unclaim(key: str) -> None:
    with _HELD_COND:
        _HELD.pop(key, None)
        _HELD_COND.notify_all()


def acquire_lock(out_dir: Path, command: str, wait: bool = False,
                 notify: Callable[[str], None] | None = None) -> tuple[int, int]:
    """Take the lock of ``out_dir`` for this thread (re-entrant within it); rank 0 only.

    Another process, or another thread of this process, holding it refuses (or, with
    ``wait``, waits). Creates the folder. Returns the number and bytes of stale temporary
    files removed.

    Raises
    ------
    OutputLockedError
        When another process or thread holds it and ``wait`` is False.
    OutputError
        When the folder cannot be created or used.
    """
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        key = os.path.realpath(out_dir)
    except OSError as exc:
        raise _folder_error(out_dir, exc) from None
    lock = out_dir / RECORD_DIR / "lock"
    if _claim(key, out_dir, command, wait, notify):
        return 0, 0
    try:
        try:
            (out_dir / RECORD_DIR).mkdir(exist_ok=True)
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise _folder_error(out_dir, exc) from None
        try:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                holder = _holder_text(lock)
                if not wait:
                    raise _locked_error(out_dir, holder) from None
                if notify is not None:
                    notify(f"waiting for the output folder {out_dir}, in use by {holder}")
                fcntl.flock(fd, fcntl.LOCK_EX)
            info = {"pid": os.getpid(), "host": socket.gethostname(), "command": command,
                    "thread": threading.get_native_id(), "started": _now()}
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(info).encode(), 0)
        except BaseException:
            os.close(fd)
            raise
    except BaseException:
        _unclaim(key)
        raise
    with _HELD_COND:
        _HELD[key][0] = fd
    try:
        return remove_stale_temps(out_dir)
    except OSError:
        return 0, 0


def _folder_error(out_dir: Path, exc: OSError) -> OutputError:
    reason = os.strerror(exc.errno) if exc.errno else os_error_text(exc)
    where = f" ({exc.filename})" if exc.filename and str(exc.filename) != str(out_dir) \
        else ""
    return OutputError(f"cannot use the output folder {out_dir}: {reason}{where}")


def release_lock(out_dir: Path) -> None:
    """Release one level of this thread's lock of ``out_dir`` (rank 0); a lock that another
    thread holds is left alone."""
    key = os.path.realpath(out_dir)
    with _HELD_COND:
        held = _HELD.get(key)
        if held is None or held[2] != threading.get_ident() or held[0] is None:
            return
        held[1] -= 1
        if held[1] > 0:
            return
        fd = held[0]
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)
        del _HELD[key]
        _HELD_COND.notify_all()


def holds_lock(out_dir: Path) -> bool:
    """True when this thread holds the lock of ``out_dir``."""
    held = _HELD.get(os.path.realpath(out_dir))
    return held is not None and held[2] == threading.get_ident() and held[0] is not None


@contextlib.contextmanager
def output_lock(out_dir: str | os.PathLike, comm, command: str, wait: bool = False,
                rep=None) -> Iterator[None]:
    """Hold the lock of ``out_dir`` for the block (collective; rank 0 holds it).

    Re-entrant within a thread: stages called by a command that holds the lock do not lock
    again. Another thread of this process is kept out like another process. Prints how
    many temporary files of interrupted runs were removed.
    """
    from ..parallel import on_root

    out_dir = Path(out_dir)
    notify = rep.info if rep is not None else None
    if wait and comm is not None and comm.size > 1:
        count, nbytes = _root_while_others_sleep(
            lambda: acquire_lock(out_dir, command, wait, notify), comm)
    else:
        count, nbytes = on_root(lambda: acquire_lock(out_dir, command, wait, notify), comm)
    if count and rep is not None:
        rep.info(f"removed {count} temporary file(s) ({_size(nbytes)}) left in {out_dir} by "
                 "interrupted runs")
    try:
        yield
    finally:
        if comm is None or comm.rank == 0:
            release_lock(out_dir)


def _root_while_others_sleep(fn: Callable[[], Any], comm) -> Any:
    """Like :func:`~railvib_hpc.parallel.on_root` for a call that may block for long (waiting
    for a lock): the other ranks poll a non-blocking receive and sleep, instead of spinning
    in a broadcast."""
    import time

    from ..parallel import root_outcome, settle

    tag = 7316
    original = None
    if comm.rank == 0:
        outcome, original = root_outcome(fn)
        for r in range(1, comm.size):
            comm.send(outcome, dest=r, tag=tag)
    else:
        req = comm.irecv(source=0, tag=tag)
        while True:
            done, outcome = req.test()
            if done:
                break
            time.sleep(0.2)
    return settle(outcome, original)


# ----------------------------------------------------------------------------- misc
def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def copy_file(src: Path, dst: Path) -> None:
    """Copy ``src`` to ``dst`` atomically (temporary name, rename)."""
    with atomic_file(dst) as tmp:
        shutil.copyfile(src, tmp)
