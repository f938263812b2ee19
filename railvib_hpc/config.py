"""The case: load and merge a case file into a validated, immutable :class:`Case`.

A case is a TOML file whose keys are described in :mod:`railvib_hpc.schema`.
Loading merges, in this order: schema defaults, the chosen preset, the file,
then ``--set key=value`` overrides. Validation (:mod:`railvib_hpc.validation`)
collects *all* problems and raises one :class:`~railvib_hpc.errors.CaseError`
naming key, value and what is allowed for each.
"""

from __future__ import annotations

import copy
import difflib
import json
import os
import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tomllib

from .errors import CaseError
from .io.digests import digest, hash_file
from .io.products import flat_case
from .schema import PRESETS, SCHEMA
from .site import derive_keys
from .validation import ALL_KEYS, check_consistency, check_value

#: Shortest wavelength of the FRA spectra's fitted range (5 ft; Hamid et al., FRA 1980) [m].
FRA_FITTED_WAVELENGTH_MIN = 1.524
_SECTION_KEYS = {k.rsplit(".", 1)[0] for k in ALL_KEYS}
#: The kinds of key written as a list of tables (``[[soil.layers]]``), with what one is.
_TABLE_LISTS = {"layers": "layer", "probe_lines": "line"}


class CaseKeyError(KeyError):
    """A key that is not in the case (``case["mesh.nope"]``), with a did-you-mean.

    A :class:`KeyError`, so :meth:`Case.get`, ``in`` and mapping code treat it as a missing
    key; not a :class:`~railvib_hpc.errors.UserError`: a wrong key in the program's own
    code stays an internal error ("please report"), not a one-line user error.

    Parameters
    ----------
    key
        The dotted key asked for.
    hint
        What is wrong (default: the did-you-mean of a case-file key).
    """

    def __init__(self, key: str, hint: str | None = None):
        self.key, self.hint = key, hint or _did_you_mean(key)
        super().__init__(f"case key {key!r}: {self.hint}")

    def __str__(self) -> str:                 # KeyError would quote the whole message
        return str(self.args[0])

    def __reduce__(self):
        return (type(self), (self.key, self.hint))


#: Why :meth:`Case.from_dict` refuses an empty mapping (as :func:`load_case` an empty file).
_EMPTY_CASE = ("sets no key: it would run the built-in defaults; to run the thesis baseline "
               "use Case.defaults() (or jobs/thesis_baseline.toml)")


@dataclass(frozen=True)
class Case:
    """A validated case: every schema key with a typed value. Immutable.

    Make one with :meth:`from_file`, :meth:`from_dict` or :meth:`defaults`; derive
    variants with :meth:`replace`, which validates like a case file (the same
    :class:`~railvib_hpc.errors.CaseError` lines as the command line) and returns a new
    case.

    Attributes
    ----------
    data
        Nested dict with every schema key filled in (read it, never modify it:
        ``case[key]`` returns copies of sections and lists).
    path
        The case file (``None`` for the built-in defaults or a dict); relative paths in
        the case (``mesh.file``, ``irregularity.file``) are resolved against its folder.
    notes
        Things the user should know that are not errors (e.g. preset values
        overridden by the file).
    given
        The entries the file, the dict and the overrides gave (dotted keys), from which
        :meth:`replace` rebuilds the case (so a changed ``case.preset`` applies its
        values).

    Examples
    --------
    >>> case = Case.defaults()
    >>> case["materials.subgrade.E"]
    200000000.0
    >>> soft = case.replace({"materials.subgrade.E": 1.5e8, "vehicle.speed": 20})
    >>> soft["materials.subgrade.E"], soft["vehicle.speed"], case["vehicle.speed"]
    (150000000.0, 20.0, 30.0)
    >>> case.replace({"materials.subgrade.E": -1.0})  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    railvib_hpc.errors.CaseError: invalid case file: materials.subgrade.E = -1.0: must be > 0 ...
    """

    data: dict[str, Any]
    path: Path | None = None
    notes: tuple[str, ...] = ()
    given: dict[str, Any] | None = field(default=None, repr=False, compare=False)

    # --------------------------------------------------------------- constructors
    @classmethod
    def from_file(cls, path: str | os.PathLike, overrides: Mapping[str, Any] | Sequence[str]
                  | None = None) -> Case:
        """Read and validate a TOML case file.

        Parameters
        ----------
        path
            The case file.
        overrides
            ``{dotted key: value}`` with typed values (``{"modal.n_modes": 20}``), or
            ``["key=value", ...]`` strings as given to ``--set``.

        Raises
        ------
        CaseError
            Every problem of the file and the overrides, as the command line prints them.
        """
        if overrides is None or isinstance(overrides, Mapping):
            case = load_case(path)
            return case.replace(overrides) if overrides else case
        if isinstance(overrides, str):
            overrides = [overrides]
        return load_case(path, list(overrides))

    @classmethod
    def from_dict(cls, mapping: Mapping[str, Any], path: str | os.PathLike | None = None
                  ) -> Case:
        """Validate a case given as a (nested, TOML-like, or flat dotted-key) mapping.

        Keys not given take their preset's or the schema's defaults. ``path``: a file
        whose folder relative paths in the case refer to (default: the current folder).

        Examples
        --------
        >>> case = Case.from_dict({"case": {"name": "soft"}, "vehicle.speed": 25.0})
        >>> case["case.name"], case["vehicle.speed"]
        ('soft', 25.0)

        Raises
        ------
        CaseError
            Every invalid entry; an empty mapping, like an empty case file, is refused (it
            would silently be the thesis baseline: :meth:`defaults` says so).
        TypeError
            When ``mapping`` is not a mapping (e.g. a :class:`Case`).
        """
        if not isinstance(mapping, Mapping):
            raise TypeError(f"Case.from_dict takes a mapping of case keys, not "
                            f"{type(mapping).__name__}")
        if not mapping:
            raise CaseError([("case dict", {}, _EMPTY_CASE)])
        return build_case(dict(mapping), None, Path(path).resolve() if path else None)

    @classmethod
    def defaults(cls) -> Case:
        """The built-in defaults: the thesis baseline (``jobs/thesis_baseline.toml``)."""
        return build_case({}, None, None)

    # --------------------------------------------------------------- derived cases
    def replace(self, changes: Mapping[str, Any] | None = None, /, **sections: Any) -> Case:
        """A new validated case with some values changed (this one is unchanged).

        Parameters
        ----------
        changes
            ``{dotted key: value}``; values are typed (numbers, strings, lists, booleans)
            and checked like a case file's; a section's dict (``{"vehicle": {...}}``)
            sets several keys of it.
        **sections
            Plain keywords for top-level sections, e.g. ``vehicle={"speed": 20}``.

        Raises
        ------
        CaseError
            Naming every invalid key and value.
            A key given twice with different values (``{"vehicle.speed": 20.0,
            "vehicle": {"speed": 25.0}}``, or in ``changes`` and a keyword) is refused,
            naming both spellings.
        TypeError
            When ``changes`` is not a mapping, e.g. another :class:`Case` (which has no
            "changes": use it as it is, or pass ``other.given``, the entries it sets).
        """
        if changes is not None and not isinstance(changes, Mapping):
            also = (" (another case: use it as it is, or pass its .given, the entries it "
                    "sets)" if isinstance(changes, Case) else "")
            raise TypeError("Case.replace takes {dotted key: value} changes, not "
                            f"{type(changes).__name__}{also}")
        flat = dict(self.given) if self.given is not None else flat_case(self.data)
        flat.update(flat_entries(dict(changes or {}), sections))
        return build_case(flat, None, self.path)

    def __hash__(self) -> int:
        """The hash of the case's digest (with its path and notes), consistent with
        ``==``, which compares the values, the path and the notes: a case can be a dict
        key or a set member.

        Examples
        --------
        >>> a, b = Case.defaults(), Case.defaults()
        >>> a == b and hash(a) == hash(b) and len({a, b, a.replace({"vehicle.speed": 20})})
        2
        """
        cached = self.__dict__.get("_hash")
        if cached is None:
            cached = hash((digest(self.data), self.path, self.notes))
            object.__setattr__(self, "_hash", cached)      # frozen: computed once
        return cached

    # --------------------------------------------------------------- reading
    def __getitem__(self, dotted: str) -> Any:
        """The value of a dotted key, or a copy of a section (``case["geometry"]``).

        Raises
        ------
        CaseKeyError
            A :class:`KeyError` naming the key and the nearest case key.
        """
        if not isinstance(dotted, str):
            raise CaseKeyError(repr(dotted), "case keys are dotted strings, e.g. "
                                             "'vehicle.speed'")
        node: Any = self.data
        for k, part in enumerate(parts := dotted.split(".")):
            if not isinstance(node, dict):
                raise CaseKeyError(dotted, f"{'.'.join(parts[:k])} is a value, not a section")
            if part not in node:
                raise CaseKeyError(dotted)
            node = node[part]
        return copy.deepcopy(node) if isinstance(node, dict | list) else node

    def __contains__(self, dotted: object) -> bool:
        try:
            self[dotted]  # type: ignore[index]
        except KeyError:
            return False
        return True

    def get(self, dotted: str, default: Any = None) -> Any:
        """``case[dotted]``, or ``default`` when the key does not exist."""
        try:
            return self[dotted]
        except (KeyError, TypeError):
            return default

    def section(self, name: str) -> dict[str, Any]:
        """Return a copy of one section, e.g. ``case.section("geometry")``."""
        return self[name]

    def to_dict(self) -> dict[str, Any]:
        """A deep copy of the nested case (e.g. to edit and pass to :meth:`from_dict`)."""
        return copy.deepcopy(self.data)

    def flat(self) -> dict[str, Any]:
        """Every key as ``{dotted key: value}`` (copies)."""
        return copy.deepcopy(flat_case(self.data))

    def digest(self, *sections: str, exclude: Collection[str] = ()) -> str:
        """SHA-256 of the given sections (all if none), for result reuse keys.

        Keys named in ``exclude`` are left out at every depth (e.g. damping ratios, which
        do not change the modes).
        """
        names = sections or tuple(sorted(self.data))

        def drop(node: Any) -> Any:
            if not isinstance(node, dict):
                return node
            return {k: drop(v) for k, v in node.items() if k not in exclude}

        payload = {n: drop(self.data[n]) if "." not in n else drop(self[n]) for n in names}
        if "mesh" in names and self["mesh.file"]:
            payload["mesh_file_sha256"] = hash_file(self.resolve(self["mesh.file"]))
        return digest(payload)

    def resolve(self, relative: str) -> Path:
        """Resolve a path given in the case file relative to the file's folder."""
        p = Path(relative)
        if not p.is_absolute() and self.path is not None:
            p = self.path.parent / p
        return p

    def to_toml(self) -> str:
        """Serialise the full, merged case as TOML (for provenance)."""
        return dumps_toml(self.data)


def defaults() -> dict[str, Any]:
    """Nested dict of all schema defaults."""
    out: dict[str, Any] = {}
    for key, param in ALL_KEYS.items():
        _set(out, key, copy.deepcopy(param.default))
    return out


def _set(tree: dict[str, Any], dotted: str, value: Any) -> None:
    parts = dotted.split(".")
    for p in parts[:-1]:
        tree = tree.setdefault(p, {})
    tree[parts[-1]] = value


def _did_you_mean(key: str) -> str:
    candidates = list(ALL_KEYS) + sorted(_SECTION_KEYS)
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.6)
    if not close:
        # compare the last component only (e.g. a misspelt key in the right section)
        leaf = key.rsplit(".", 1)[-1]
        by_leaf = {k.rsplit(".", 1)[-1]: k for k in ALL_KEYS if k.startswith(key.rsplit(".", 1)[0])}
        m = difflib.get_close_matches(leaf, list(by_leaf), n=1, cutoff=0.6)
        close = [by_leaf[m[0]]] if m else []
    section = key.split(".")[0]
    known = ", ".join(sorted(SCHEMA)) if section not in SCHEMA else None
    if close:
        return f"unknown key; did you mean '{close[0]}'?"
    if known:
        return f"unknown section '{section}'; sections are: {known}"
    return f"unknown key; see docs/case_reference.md (section [{section}])"


def parse_override(text: str) -> tuple[str, Any]:
    """Parse one ``--set key=value``; the value is read as a TOML value.

    Unquoted text that is not valid TOML is taken as a string, also inside a flat list,
    so ``--set vehicle.type=wheelset`` and ``--set output.probe_roles=[floor,wall]`` work
    without quotes.
    """
    if "=" not in text:
        raise CaseError([(text, None, "an override must look like key=value, "
                          "e.g. --set mesh.refinement=2")])
    key, raw = text.split("=", 1)
    return key.strip(), toml_value(raw.strip())


def toml_value(raw: str) -> Any:
    """A TOML value; unquoted words are strings, also inside a flat list (``[a, b]``)."""
    try:
        return tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        pass
    if raw.startswith("[") and raw.endswith("]") and "[" not in raw[1:-1]:
        return [toml_value(x.strip()) for x in raw[1:-1].split(",") if x.strip()]
    return raw


def _spelling(path: tuple[str, ...]) -> str:
    """How a key was written in a mapping: ``'vehicle.speed'`` or ``'vehicle' -> 'speed'``."""
    return " -> ".join(repr(p) for p in path)


def flat_entries(*mappings: Mapping[str, Any]) -> dict[str, Any]:
    """The entries of (nested or dotted-key) mappings as ``{dotted key: value}``.

    A key given twice with different values, in two spellings (``{"vehicle.speed": 20.0,
    "vehicle": {"speed": 25.0}}``) or in two of the mappings, is refused (the same value
    twice is accepted: nothing is ambiguous).

    Raises
    ------
    CaseError
        One line per such key, naming both spellings and their values.

    Examples
    --------
    >>> flat_entries({"vehicle.speed": 20.0, "vehicle": {"type": "wheelset"}})
    {'vehicle.speed': 20.0, 'vehicle.type': 'wheelset'}
    >>> flat_entries({"vehicle.speed": 20.0, "vehicle": {"speed": 25.0}})
    Traceback (most recent call last):
    ...
    railvib_hpc.errors.CaseError: invalid case file: vehicle.speed = 20.0: given twice ...
    """
    out: dict[str, Any] = {}
    spelled: dict[str, tuple[str, ...]] = {}
    problems: list[tuple[str, Any, str]] = []

    def walk(node: Mapping[str, Any], path: tuple[str, ...]) -> None:
        for k, v in node.items():
            here = (*path, str(k))
            if isinstance(v, Mapping):
                walk(v, here)
                continue
            key = ".".join(here)
            if key in out and not _same(out[key], v):
                problems.append((key, out[key], f"given twice with different values, as "
                                 f"{_spelling(spelled[key])} = {out[key]!r} and as "
                                 f"{_spelling(here)} = {v!r}: give it once"))
                continue
            out[key], spelled[key] = v, here

    for mapping in mappings:
        walk(mapping, ())
    if problems:
        raise CaseError(problems)
    return out


def _same(a: Any, b: Any) -> bool:
    """Equal values (numbers by value, 20 == 20.0; anything uncomparable differs)."""
    try:
        return bool(a == b)
    except (TypeError, ValueError):                   # e.g. numpy arrays
        return False


def _group_tables(flat: dict[str, Any]) -> None:
    """Gather the dotted keys of a table-valued key (``train2.vehicle.car_mass``) into it."""
    for key, param in ALL_KEYS.items():
        if param.kind != "vehicle":
            continue
        inner = {k[len(key) + 1:]: flat.pop(k) for k in [k for k in flat
                                                         if k.startswith(key + ".")]}
        if inner:
            given = flat.get(key, {})
            flat[key] = {**(given if isinstance(given, dict) else {}), **inner}


def build_case(raw: dict[str, Any], overrides: list[str] | None = None,
               path: Path | None = None) -> Case:
    """Merge defaults, preset, ``raw`` (parsed TOML) and overrides; validate.

    Raises
    ------
    CaseError
        With every problem found.
    """
    problems: list[tuple[str, Any, str]] = []
    flat = flat_entries(raw)       # values made plain by check_value (_plain)
    for text in overrides or []:
        key, value = parse_override(text)
        flat[key] = value
    _group_tables(flat)
    for key in list(flat):
        if key not in ALL_KEYS:
            table = next((k for k, prm in ALL_KEYS.items() if prm.kind in _TABLE_LISTS
                          and key.startswith(k + ".")), None)
            hint = (f"{table} is a list of tables: write [[{table}]] (double brackets), one "
                    f"per {_TABLE_LISTS[ALL_KEYS[table].kind]}" if table else _did_you_mean(key))
            problems.append((key, flat.pop(key), hint))

    preset = flat.get("case.preset", ALL_KEYS["case.preset"].default)
    data = defaults()
    if isinstance(preset, str) and preset in PRESETS:
        for key, value in PRESETS[preset].items():
            _set(data, key, value)
    for key, value in flat.items():
        _set(data, key, check_value(key, ALL_KEYS[key], value, problems))
    if problems:
        raise CaseError(problems)
    derived, problems = derive_keys(flat_case(data), flat)   # [site], X4, the sleepers...
    if problems:
        raise CaseError(problems)
    for key, value in derived.items():
        _set(data, key, value)
    notes = []
    if isinstance(preset, str) and PRESETS.get(preset):
        shadowed = [k for k, v in PRESETS[preset].items() if k in flat and flat[k] != v]
        if shadowed:
            notes.append(f"case.preset = '{preset}' sets {len(PRESETS[preset])} keys, but the "
                         f"file or --set gives other values for {len(shadowed)} of them, which "
                         f"win: {', '.join(shadowed)}")
    irr = data["irregularity"]
    if irr["type"] == "fra" and irr["wavelength_min"] < FRA_FITTED_WAVELENGTH_MIN:
        notes.append(f"irregularity.wavelength_min = {irr['wavelength_min']:g} m lies below the "
                     f"range the FRA spectra were fitted to (>= {FRA_FITTED_WAVELENGTH_MIN} m = "
                     "5 ft): the shorter wavelengths are an extrapolation")
    case = Case(data=data, path=path, notes=tuple(notes), given=copy.deepcopy(flat))
    problems.extend(check_consistency(case))
    if problems:
        raise CaseError(problems)
    return case


def load_case(path: str | Path | None, overrides: list[str] | None = None) -> Case:
    """Read a TOML case file (``None``: built-in defaults) and validate it.

    A file that sets no key at all (empty, or only comments) is refused: it would
    silently run the built-in thesis baseline, which is more likely a broken copy than
    an intent (``jobs/thesis_baseline.toml`` lists every key for that).

    Raises
    ------
    CaseError
        Missing, unreadable, empty or too deeply nested file, a directory, TOML syntax
        errors, or invalid entries.
    """
    raw: dict[str, Any] = {}
    p: Path | None = None
    if path is not None:
        p = Path(path)
        if p.is_dir():
            raise CaseError([("case file", str(path), "is a directory; give the TOML file, "
                              "e.g. jobs/thesis_baseline.toml")])
        if not p.is_file():
            raise CaseError([("case file", str(path), "file not found")])
        try:
            text = p.read_text()
        except UnicodeDecodeError:
            raise CaseError([("case file", str(path), "not a text (UTF-8) file")]) from None
        except OSError as exc:
            reason = os.strerror(exc.errno) if exc.errno else str(exc)
            raise CaseError([("case file", str(path), f"cannot be read ({reason})")]) from None
        try:
            raw = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise CaseError([("case file", str(path), f"not valid TOML: {exc}")]) from None
        except RecursionError:
            raise CaseError([("case file", str(path), "not valid TOML: nested too deeply")]) \
                from None
        if not raw:
            raise CaseError([("case file", str(path), "sets no key (empty or only comments): "
                              "it would run the built-in defaults; to run the thesis baseline "
                              "use jobs/thesis_baseline.toml")])
        p = p.resolve()
    return build_case(raw, overrides, p)


def results_folder_name(name: str) -> str:
    """``case.name`` as a safe folder name for the default ``results/<name>``: anything but
    letters, digits, ``.``, ``_``, ``-`` becomes ``_``, leading/trailing dots and
    underscores are dropped (no ``..``, no absolute paths), at most 100 characters.

    Examples
    --------
    >>> results_folder_name("../../x"), results_folder_name("/tmp/a b")
    ('x', 'tmp_a_b')
    """
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._")[:100].strip("._")
    return safe or "case"


def dumps_toml(tree: dict[str, Any]) -> str:
    """Minimal TOML writer for nested dicts of scalars and lists (provenance only)."""
    lines: list[str] = []

    def scalar(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, float):
            return repr(v)
        if isinstance(v, list):
            return "[" + ", ".join(scalar(x) for x in v) + "]"
        if isinstance(v, dict):          # a table in a list: [[soil.layers]] as inline tables
            return "{" + ", ".join(f"{k} = {scalar(x)}" for k, x in v.items()) + "}"
        return str(v)

    def walk(node: dict[str, Any], path: str) -> None:
        leaves = {k: v for k, v in node.items() if not isinstance(v, dict)}
        if leaves:
            if path:
                lines.append(f"[{path}]")
            lines.extend(f"{k} = {scalar(v)}" for k, v in leaves.items())
            lines.append("")
        for k, v in node.items():
            if isinstance(v, dict):
                walk(v, f"{path}.{k}" if path else k)

    walk(tree, "")
    return "\n".join(lines)
