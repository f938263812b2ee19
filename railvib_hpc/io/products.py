"""The product table's machinery: rows, the table, the case keys' selection and digests.

:data:`STAGE_FILES` names, for each result file, the command that writes it, its format
version, the case keys it depends on (cumulatively: a file depends on everything its
upstream files depend on), the upstream files it reads, its companion files and its data
check; :func:`inputs_hash` is the digest of those keys (and of the external files they
name), which each file records (:mod:`railvib_hpc.io.provenance`).

Each row (a :class:`StageFile`) is declared once, by the module of the stage that writes
it, with that stage (its ``STAGE``'s products: e.g. :data:`railvib_hpc.mesh.stage.MESH_KEYS`
and ``MESH_FILE``); the studies' ``result.json`` by :mod:`railvib_hpc.studies.common`.
A row names the keys it adds and the products whose keys it takes over
(:attr:`StageFile.extends`: ``modes.h5`` extends ``mesh.h5``, ``mbs.h5`` extends
``modes.h5``): the cumulative selection (:attr:`StageFile.inputs`) is resolved here, by
table name, so no stage module imports another's keys.
This module holds only what every row shares; the table is filled as the stage modules
are imported, and wholly (through the registry, :data:`REGISTRY`) when it is read whole or
for a name it lacks. The rows, for reference:

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
:data:`STAGE_FILES` (a :class:`ProductTable` of rows :class:`StageFile`, added by
:func:`declare`), :data:`ALL_KEYS`, :func:`spec`, :func:`whole_sections`,
:func:`flat_case`, :func:`select` (a :data:`Selection` of case keys),
:func:`external_files`, :func:`inputs_hash`.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Iterator, Mapping, MutableMapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..schema import iter_params
from .digests import digest, hash_file
from .stage_checks import CHECKS

#: Sections whose defaults are the model as it was before they existed (``[site]``: no key
#: given, the geometry keys apply; ``[probes]``: no probe lines). A key of theirs at its
#: default stays out of every inputs digest, so a case that does not use them keeps the
#: digests, and the results, it had (the golden record, ``tests/data/golden_run.json``,
#: stands). A given site key's effect is in the geometry keys it sets (hashed anyway).
#: ``[load]``: no moving surface load.
DIGEST_NEUTRAL_SECTIONS = ("site", "probes", "uncertainty", "load")
#: Keys that only decide whether a stage accepts what it computed (a check's limit), never
#: what a file holds: they enter no inputs digest, and the stage checks a reused file again.
CHECK_ONLY_KEYS = ("mesh.max_dispersion_error", "vehicle.supercritical")

#: A selection of case keys: (dotted prefix, leaf names left out below it).
Selection = tuple[tuple[str, tuple[str, ...]], ...]

#: Every case key: the products that depend on the whole case (``assessment.json``,
#: ``result.json``).
ALL_KEYS: Selection = (("", ()),)


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
    keys
        The case keys it adds to those of :attr:`extends` (all of them when it extends
        nothing); :attr:`inputs` is the whole selection.
    upstream
        The files it is computed from (those in parentheses in the module table are read
        only with the static correction).
    companions
        Files written with it that must exist for it to be reused (XDMF, reports).
    input_files
        Case keys naming external files whose content is part of the inputs.
    file
        The file name on disk when it is not the table name (the transient stage's
        ``fields.h5`` and ``probes.h5``).
    check
        Its data check (``check(path, full, context)``: a list of problems; one of
        :mod:`railvib_hpc.io.formats`), run on write and on reuse; not part of the row's
        identity.
    extends
        The table names of the products whose case keys it depends on too (its upstream
        products': ``modes.h5`` extends ``mesh.h5``), so a row declares only the keys it
        adds and no stage imports another's keys: the table resolves them
        (:attr:`inputs`) when they are read.
    check_context
        ``check_context(case, out_dir) -> dict``: what its data check needs of the case
        and the folder (``mbs.h5``: the static wheel load and the modes file), for a
        stage that verifies it as an input
        (:meth:`~railvib_hpc.io.stage_protocol.StageContext.require`); not part of the
        row's identity.
    """

    name: str
    stage: str
    version: int
    keys: Selection
    upstream: tuple[str, ...] = ()
    companions: tuple[str, ...] = ()
    input_files: tuple[str, ...] = ()
    file: str = ""
    check: Callable | None = field(default=None, compare=False, repr=False)
    extends: tuple[str, ...] = ()
    check_context: Callable | None = field(default=None, compare=False, repr=False)

    @property
    def filename(self) -> str:
        """The file name in the output folder (``file``, or the table name)."""
        return self.file or self.name

    @property
    def inputs(self) -> Selection:
        """The case keys it depends on, cumulative: those of the products it
        :attr:`extends` (resolved through :data:`STAGE_FILES`, recursively), then its own
        :attr:`keys`, each entry once, in that order."""
        out: list = []
        for name in self.extends:
            out += [k for k in spec(name).inputs if k not in out]
        return tuple(out + [k for k in self.keys if k not in out])


class ProductTable(MutableMapping):
    """The product table, table name -> :class:`StageFile`: each row is declared by the
    module of the stage that writes it (its ``STAGE``'s products, added by
    :func:`declare`), so adding a stage adds its rows here.

    Reading a name it lacks, or the whole table, first imports the registry's modules
    (:data:`REGISTRY`'s ``declare_products``: every registered stage's module, by name, as
    :mod:`railvib_hpc.pipeline` imports them), so the table is whole wherever it is read.
    """

    def __init__(self) -> None:
        self._rows: dict[str, StageFile] = {}
        self._whole = False
        self._declaring = False

    def declare_all(self) -> None:
        """Declare every registered product (once; nothing while it declares them)."""
        if self._whole or self._declaring:
            return
        self._declaring = True
        try:
            importlib.import_module(REGISTRY).declare_products()
            self._whole = True
        finally:
            self._declaring = False

    def declared(self, name: str) -> StageFile | None:
        """The row of ``name`` if it is declared already (imports nothing)."""
        return self._rows.get(name)

    def __getitem__(self, name: str) -> StageFile:
        if name not in self._rows:
            self.declare_all()
        return self._rows[name]

    def __contains__(self, name: object) -> bool:
        if name not in self._rows:
            self.declare_all()
        return name in self._rows

    def __setitem__(self, name: str, row: StageFile) -> None:
        self._rows[name] = row

    def __delitem__(self, name: str) -> None:
        del self._rows[name]

    def __iter__(self) -> Iterator[str]:
        self.declare_all()
        return iter(dict(self._rows))

    def __len__(self) -> int:
        self.declare_all()
        return len(self._rows)

    def __repr__(self) -> str:
        return f"ProductTable({list(self._rows)!r})"


#: The module whose ``declare_products()`` imports the modules that declare the products
#: (the registry of the stages; imported by name, never by the io layer's code).
REGISTRY = "railvib_hpc.pipeline"

#: The one product table (rows declared by the stage modules).
STAGE_FILES: ProductTable = ProductTable()


def declare(row: StageFile) -> str:
    """Add a product's row to :data:`STAGE_FILES` (its check, if any, to the checks'
    table, :data:`~railvib_hpc.io.stage_checks.CHECKS`); returns its name.

    A row already in the table must be the same row (a product is declared once).

    Raises
    ------
    ValueError
        For another row under a name the table already has.
    """
    known = STAGE_FILES.declared(row.name)
    if known is not None and known != row:
        raise ValueError(f"{row.name} is already a stage file of 'railvib {known.stage}'")
    STAGE_FILES[row.name] = row
    if row.check is not None:
        CHECKS.setdefault(row.name, row.check)
    return row.name


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
#: default is the model that was there before them: the rigid track ends; the perfectly
#: matched layers' parameters, which act on pml faces only; the building, present by
#: default).
NEUTRAL_AT_DEFAULT_KEYS = ("track.ends", "track.end_stiffness", "track.end_damping",
                           # the perfectly matched layers' parameters
                           "boundary.pml_reflection", "boundary.pml_power",
                           "boundary.pml_alpha",
                           # the optional building: its default is the site there was
                           "building.present",
                           # the soil's element order: its default is today's trilinear
                           # element
                           "mesh.order")

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
