"""The product table: each stage file's stage, format version, case keys and upstream files.

:data:`STAGE_FILES` names, for each result file, the command that writes it, its format
version, the case keys it depends on (cumulatively: a file depends on everything its
upstream files depend on) and the upstream files it reads; :func:`inputs_hash` is the
digest of those keys (and of the external files they name), which each file records
(:mod:`railvib_hpc.io.provenance`):

===============  ===========  ==========================================  ===================
file             written by   case keys (inputs)                          upstream files
===============  ===========  ==========================================  ===================
mesh.h5          mesh         geometry, track (without end_stiffness,     --
                              end_damping), building, mesh, domain,
                              the content of ``mesh.file``
modes.h5         modal        + materials, sections, pads, modal (without  mesh.h5
                              damping settings, ``modal.out_of_core``
                              and the band split), boundary, the
                              random fields (uncertainty.field,
                              realisation, seed)
static.h5        modal        as modes.h5                                 mesh.h5, modes.h5
modal_damping.h5 modal        + pads, [damping]                           mesh.h5, modes.h5
bands/index.json modal        as modes.h5, without f_max, n_modes,        --
                              max_basis, shift_hz (the band cache,
                              :mod:`~railvib_hpc.io.formats.bands`)
mbs.h5           mbs          + damping settings, [damping], vehicle,     modes.h5
                              irregularity (and its file), mbs            (static.h5,
                                                                          modal_damping.h5)
fields.h5        reconstruct  + output.dt, window, float32,               modes.h5, mbs.h5
                              static_correction_rates                     (static.h5)
probes.h5        reconstruct  + output.window, probes,                    modes.h5, mbs.h5
                              static_correction_rates, [probes]           (static.h5)
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
                                       automatic step divides it),
                                       track.end_stiffness, end_damping
transient:fields.h5       transient    + output.window, float32                mesh.h5
(fields.h5)                            (``/stress`` records its own hash with
                                       output.stress_times)
transient:probes.h5       transient    + output.probes, probe_roles, [probes]  mesh.h5
(probes.h5)
transient_checkpoint.h5   transient    the union of the three above (it        mesh.h5
                                       resumes all of them)
========================  ===========  ======================================  =============

The keys of :data:`DIGEST_NEUTRAL_SECTIONS` (``[site]``, ``[probes]``, ``[uncertainty]``: the
random fields enter the modes, the passage and the full-order solution) enter an inputs
digest only where they differ from their defaults; those of :data:`CHECK_ONLY_KEYS`
(``mesh.max_dispersion_error``, ``vehicle.supercritical``) never.

The three products come from one time integration: they are reused only together, and
one stale or missing product recomputes all three. The checkpoint is resumed only when
it is current and sound by the same rules as a result, and the partial ``fields.h5``
(:func:`~railvib_hpc.io.temp_names.resume_path`) carries the same run id.

API
---
:data:`STAGE_FILES` (rows :class:`StageFile`), :func:`spec`, :func:`whole_sections`,
:func:`flat_case`, :func:`select` (a :data:`Selection` of case keys),
:func:`external_files`, :func:`inputs_hash`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..schema import iter_params
from .digests import digest, hash_file
from .files import (
    ASSESSMENT_JSON,
    BAND_CACHE,
    FIELDS_H5,
    FIELDS_XDMF,
    MBS_H5,
    MESH_H5,
    MESH_REPORT_JSON,
    MESH_XDMF,
    MODAL_DAMPING_H5,
    MODES_H5,
    MODES_XDMF,
    PROBES_H5,
    REPORT_HTML,
    REPORT_JSON,
    REPORT_MD,
    RESULT_JSON,
    STATIC_H5,
    TRANSIENT_CHECKPOINT_H5,
    TRANSIENT_FIELDS,
    TRANSIENT_H5,
    TRANSIENT_PROBES,
)

#: Sections whose defaults are the model as it was before they existed (``[site]``: no key
#: given, the geometry keys apply; ``[probes]``: no probe lines). A key of theirs at its
#: default stays out of every inputs digest, so a case that does not use them keeps the
#: digests, and the results, it had (the golden record, ``tests/data/golden_run.json``,
#: stands). A given site key's effect is in the geometry keys it sets (hashed anyway).
DIGEST_NEUTRAL_SECTIONS = ("site", "probes", "uncertainty")
#: Keys that only decide whether a stage accepts what it computed (a check's limit), never
#: what a file holds: they enter no inputs digest, and the stage checks a reused file again.
CHECK_ONLY_KEYS = ("mesh.max_dispersion_error", "vehicle.supercritical")

#: A selection of case keys: (dotted prefix, leaf names left out below it).
Selection = tuple[tuple[str, tuple[str, ...]], ...]

#: The mesh: its geometry and divisions, the soil layers, the elastic interfaces (they cut
#: the mesh), and the soils' E, nu, rho (the wavelength sizing, mesh.elements_per_wavelength,
#: reads their shear-wave speeds).
_SOIL_WAVE_SPEED = ("damping_ratio",)
#: (The supported track ends' springs and dashpots are K's and C's, not the mesh's.)
_MESH = (("geometry", ()), ("track", ("end_stiffness", "end_damping")), ("building", ()),
         ("mesh", ()), ("domain", ()),
         ("soil", ()), ("trench", ()), ("wib", ()), ("usp", ()), ("ballast_mat", ()),
         ("isolation", ()), ("materials.ballast", _SOIL_WAVE_SPEED),
         ("materials.subballast", _SOIL_WAVE_SPEED), ("materials.subgrade", _SOIL_WAVE_SPEED))
#: The random fields of the soil layers (the element matrices: ``Problem.fields``); at
#: their defaults (realisation 0: no field) they enter no digest.
_RANDOM_FIELDS = (("uncertainty.field", ()), ("uncertainty.realisation", ()),
                  ("uncertainty.seed", ()))
#: A sample of the reduced model (``uncertainty.basis``: its modes are the reduced model's
#: on the basis's nominal mesh, or a full solve on that mesh; at their defaults, a plain
#: model, they enter no digest).
_REDUCED = (("uncertainty.basis", ()), ("uncertainty.reduced_tol", ()),
            ("uncertainty.reference", ()))
#: How the modes are computed, not what they are: the out-of-core switch and the band
#: split with its parallel layout (they change the modes by round-off only).
MODAL_SOLVER_LAYOUT = ("out_of_core", "bands", "band_modes", "band_groups", "band_only")
#: The damping settings of [modal] and [pads] (and the materials' ratios): not the modes.
MODAL_DAMPING_KEYS = ("damping_ratio", "damping")
#: Damping settings and the solver layout do not change the modes.
MODAL_ONLY_EXCLUDED = (*MODAL_DAMPING_KEYS, *MODAL_SOLVER_LAYOUT)
#: A band of the band-sliced solve (its cache in ``<out>/bands``) depends on [modal] as the
#: modes do, except on how many modes up to which frequency are wanted and on the basis
#: and shift of an unsliced solve: the band cache's inputs leave them out, so raising
#: ``modal.f_max`` keeps the cache and only adds bands.
BAND_EXTENT = ("f_max", "n_modes", "max_basis", "shift_hz")
_MODAL = _MESH + (("materials", MODAL_ONLY_EXCLUDED), ("sections", ()),
                  ("pads", MODAL_ONLY_EXCLUDED), ("modal", MODAL_ONLY_EXCLUDED),
                  ("boundary", ())) + _RANDOM_FIELDS + _REDUCED
_BANDS = _MESH + (("materials", MODAL_ONLY_EXCLUDED), ("sections", ()),
                  ("pads", MODAL_ONLY_EXCLUDED),
                  ("modal", (*MODAL_ONLY_EXCLUDED, *BAND_EXTENT)), ("boundary", ())
                  ) + _RANDOM_FIELDS
#: The projected parts of C (``modal.damping = 'full'``): the modes' inputs, the pads'
#: dashpots and [damping] (the ratios only enter when composed, but the whole section is
#: kept for safety). Whether the static fields are projected too is in the file's shape:
#: one with them serves a run without the static correction as well.
_MODAL_DAMPING = _MODAL + (("pads", ()), ("damping", ()))
_MBS = _MESH + (("materials", ()), ("sections", ()), ("pads", ()),
                ("modal", MODAL_SOLVER_LAYOUT), ("boundary", ()), ("damping", ()),
                ("vehicle", ()), ("train2", ()), ("irregularity", ()), ("mbs", ())
                ) + _RANDOM_FIELDS + _REDUCED
_FIELDS = _MBS + (("output.dt", ()), ("output.window", ()), ("output.float32", ()),
                  ("output.static_correction_rates", ()))
_PROBES = _MBS + (("output.window", ()), ("output.probes", ()),
                  ("output.static_correction_rates", ()), ("probes", ()))
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
                      ("output.dt", ()), ("track.end_stiffness", ()),
                      ("track.end_damping", ())) + _RANDOM_FIELDS
_TRANSIENT_FIELD_KEYS = _TRANSIENT + (("output.window", ()), ("output.float32", ()))
_TRANSIENT_PROBE_KEYS = _TRANSIENT + (("output.probes", ()), ("output.probe_roles", ()),
                                      ("probes", ()))
_TRANSIENT_STATE = _TRANSIENT_FIELD_KEYS + (("output.probes", ()), ("output.probe_roles", ()),
                                           ("probes", ()))
_FILES = ("mesh.file", "irregularity.file")


STAGE_FILES: dict[str, StageFile] = {f.name: f for f in (
    StageFile(MESH_H5, "mesh", 2, _MESH, (), (MESH_XDMF, MESH_REPORT_JSON), ("mesh.file",)),
    StageFile(MODES_H5, "modal", 2, _MODAL, (MESH_H5,), (MODES_XDMF,), ("mesh.file",)),
    StageFile(STATIC_H5, "modal", 2, _MODAL, (MESH_H5, MODES_H5), (), ("mesh.file",)),
    StageFile(MODAL_DAMPING_H5, "modal", 2, _MODAL_DAMPING, (MESH_H5, MODES_H5), (),
              ("mesh.file",)),
    StageFile(BAND_CACHE, "modal", 2, _BANDS, (), (), ("mesh.file",)),
    StageFile(MBS_H5, "mbs", 2, _MBS, (MODES_H5, STATIC_H5, MODAL_DAMPING_H5), (),
              ("mesh.file", "irregularity.file")),
    StageFile(FIELDS_H5, "reconstruct", 2, _FIELDS, (MODES_H5, MBS_H5, STATIC_H5),
              (FIELDS_XDMF,), ("mesh.file", "irregularity.file")),
    StageFile(PROBES_H5, "reconstruct", 2, _PROBES, (MODES_H5, MBS_H5, STATIC_H5),
              (), ("mesh.file", "irregularity.file")),
    StageFile(ASSESSMENT_JSON, "assess", 2, _ALL,
              (MODES_H5, STATIC_H5, MBS_H5, FIELDS_H5, PROBES_H5),
              (REPORT_MD, REPORT_HTML, REPORT_JSON), ("mesh.file", "irregularity.file")),
    StageFile(RESULT_JSON, "study", 2, _ALL, (MODES_H5, STATIC_H5, MBS_H5, PROBES_H5,
                                              TRANSIENT_H5),
              (), ("mesh.file", "irregularity.file")),
    StageFile(TRANSIENT_H5, "transient", 2, _TRANSIENT, (MESH_H5,), (), _FILES),
    StageFile(TRANSIENT_FIELDS, "transient", 2, _TRANSIENT_FIELD_KEYS, (MESH_H5,),
              (FIELDS_XDMF,), _FILES, file=FIELDS_H5),
    StageFile(TRANSIENT_PROBES, "transient", 2, _TRANSIENT_PROBE_KEYS, (MESH_H5,), (),
              _FILES, file=PROBES_H5),
    StageFile(TRANSIENT_CHECKPOINT_H5, "transient", 2, _TRANSIENT_STATE, (MESH_H5,), (),
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
    ('geometry', 'building', 'mesh', 'domain')
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


def external_files(case, keys: Sequence[str]) -> dict[str, str]:
    """Content digests of the external input files named by ``keys`` (when in use)."""
    out = {}
    for key in keys:
        if key == "irregularity.file" and case["irregularity.type"] != "file":
            continue
        if case[key]:
            out[key] = hash_file(case.resolve(case[key]))
    return out


#: Keys that enter a digest only when they differ from their default: added after the
#: products of the defaults were recorded, they leave those products current (their
#: default is the model that was there before them: issue 28's rigid track ends; issue
#: 29's layer parameters, which act on pml faces only).
NEUTRAL_AT_DEFAULT_KEYS = ("track.ends", "track.end_stiffness", "track.end_damping",
                           # issue 29: the perfectly matched layers' parameters
                           "boundary.pml_reflection", "boundary.pml_power",
                           "boundary.pml_alpha")

_NEUTRAL_DEFAULTS = {key: param.default for key, param in iter_params()
                     if key.split(".", 1)[0] in DIGEST_NEUTRAL_SECTIONS
                     or key in NEUTRAL_AT_DEFAULT_KEYS}


def _neutral(key: str, value: Any) -> bool:
    """A key of :data:`DIGEST_NEUTRAL_SECTIONS` at its default, or of :data:`CHECK_ONLY_KEYS`."""
    return key in CHECK_ONLY_KEYS or (key in _NEUTRAL_DEFAULTS
                                      and value == _NEUTRAL_DEFAULTS[key])


def hashed_keys(flat: Mapping[str, Any], selection: Selection) -> dict[str, Any]:
    """The entries of a flat case that a selection names and an inputs digest holds: those
    of :func:`select` less the keys of :data:`DIGEST_NEUTRAL_SECTIONS` at their defaults
    and of :data:`CHECK_ONLY_KEYS`."""
    return {k: v for k, v in select(flat, selection).items() if not _neutral(k, v)}


def inputs_hash(case, name: str, extra: Any = None) -> str:
    """SHA-256 of the case keys (and external files) that ``name`` depends on
    (:func:`hashed_keys`)."""
    s = spec(name)
    keys = hashed_keys(flat_case(case.data), s.inputs)
    return digest({"keys": keys, "files": external_files(case, s.input_files),
                   "extra": extra})
