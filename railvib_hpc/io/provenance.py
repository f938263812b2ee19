"""Provenance and reuse: what each stage file records, and whether the one on disk is current.

Provenance
----------
Every file records (HDF5 root attributes; a ``provenance`` object in JSON files):
``railvib_file`` (its table name), ``format_version``, ``stage``, ``inputs_sha256``
(:func:`~railvib_hpc.io.products.inputs_hash` of its case keys), ``input_files_sha256``
(content of external input files), ``upstream_sha256`` (content digests of the upstream
files it read), ``railvib_version``, ``created`` (UTC) and ``case_toml`` (the merged
case), plus ``complete = 1`` set last.

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

API
---
:func:`provenance`, :func:`read_provenance`, :func:`case_differences`, :func:`examine` ->
:class:`Verdict`, :func:`require_inputs` (raises
:class:`~railvib_hpc.errors.StaleInputError`), :func:`refuse`, :func:`rerun_hint`.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomllib

from .. import __version__
from ..errors import StaleInputError, exception_text
from .digests import file_digest, utc_now
from .products import STAGE_FILES, external_files, flat_case, hashed_keys, inputs_hash, spec


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
    files = external_files(case, s.input_files) if case is not None else {}
    return {
        "railvib_file": name, "format_version": s.version, "stage": s.stage,
        "inputs_sha256": inputs_sha256 or inputs_hash(case, name, extra),
        "input_files_sha256": json.dumps(files, sort_keys=True),
        "upstream_sha256": json.dumps(dict(upstream), sort_keys=True),
        "railvib_version": __version__, "created": utc_now(),
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
        old = hashed_keys(flat_case(tomllib.loads(stored_toml)), s.inputs)
    except (tomllib.TOMLDecodeError, TypeError) as exc:
        raise ValueError(f"the recorded case is not readable ({exc})") from None
    new = hashed_keys(flat_case(case.data), s.inputs)
    diffs = [f"{k} = {_fmt(old.get(k))}, the case says {_fmt(new.get(k))}"
             for k in sorted(set(old) | set(new)) if old.get(k) != new.get(k)]
    try:
        files_old = json.loads(stored_files or "{}")
    except ValueError:
        files_old = {}
    files_new = external_files(case, s.input_files)
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
        The expected inputs hash (default:
        :func:`~railvib_hpc.io.products.inputs_hash` of ``case``).
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
        return Verdict(False, f"it cannot be read ({exception_text(exc)})", "corrupt")
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
                           f"now ({exception_text(exc)})", "upstream", "", attrs)
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
        return Verdict(False, f"it cannot be read ({exception_text(exc)})", "corrupt", "", attrs)
    if fd.status == "changed":
        return Verdict(False, "it is corrupt (its content changed after it was written)",
                       "corrupt", fd.sha256, attrs)
    if data_check is not None:
        try:
            problems = list(data_check(path, fd.status != "recorded", dict(context or {})))
        except (OSError, ValueError, KeyError, TypeError, IndexError) as exc:
            problems = [f"it cannot be read ({exception_text(exc)})"]
        if problems:
            return Verdict(False, f"it is corrupt ({'; '.join(problems[:3])})", "corrupt",
                           fd.sha256, attrs)
    return Verdict(True, "", "ok", fd.sha256, attrs)


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
        for under its file name (:attr:`~railvib_hpc.io.products.StageFile.filename`).
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
