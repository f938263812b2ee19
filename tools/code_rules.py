"""The rules of ``make lint`` beyond ruff and the import layers: function and module
length, kernels that never take the case, file names from one place, docs that cite sources
rather than tickets, and a schema that takes nothing from the assessment.

*Function length*: no function over 150 lines unless allowed. A function's length is
counted by its syntax tree, from its ``def`` line to its last line, docstring and comments
included (decorators not). A function that must stay longer is listed in :data:`ALLOWED`
with the reason; an entry that is no longer needed (the function got shorter, or is gone)
breaks the rule too, so that the list stays short and true.

*The case boundary* (``railvib_hpc/problem.py``): a module of :data:`KERNEL_PACKAGES` is a
numerical kernel unless it is listed in :data:`TRANSLATORS`; a kernel takes arrays and the
problem object (:class:`railvib_hpc.problem.Problem`), so it may neither import from
``railvib_hpc.config`` (``Case``, ``build_case``, ..., under ``TYPE_CHECKING`` too) nor
have a parameter named ``case``. Modules still to be converted are listed in
:data:`PENDING` with the reason; an entry that no longer reads the case breaks the rule.

*File names from one place*: the package's file names (``"modes.h5"``, ...) are
the constants of ``railvib_hpc/io/files.py``; no other module of ``railvib_hpc`` spells one
as a string (docstrings, which name the files for the reader, aside).

*Module length*: no module of ``railvib_hpc`` over :data:`MAX_MODULE_LINES` lines unless
listed in :data:`LONG_MODULES` with the reason (an entry no longer needed breaks the rule).

*Sources, not tickets*: no "issue <number>" in ``railvib_hpc/``, ``docs/`` or
``README.md``: a reader needs the literature, the thesis or the reason, not an internal
ticket's number.

*The schema below the assessment*: no module of ``railvib_hpc/schema/`` (nor
``railvib_hpc/standards_registry.py``, whose names the schema takes) imports from
``railvib_hpc.assess``.

Usage::

    python tools/code_rules.py      # lists the offenders and exits with 1, if any

``tests/test_code_rules.py`` checks the same in the quick tier.
"""

from __future__ import annotations

import ast
import re
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The folders whose Python files the rule covers (those ``make lint`` checks with ruff).
FOLDERS = ("railvib_hpc", "tests", "bench", "examples", "tools")
#: The most lines a function may have.
MAX_FUNCTION_LINES = 150
#: Functions allowed over :data:`MAX_FUNCTION_LINES`: ``"path::qualified.name": reason``.
ALLOWED: dict[str, str] = {}


def function_lengths(root: Path = ROOT) -> Iterator[tuple[str, int]]:
    """Yield ``("path::qualified.name", lines)`` for every function under :data:`FOLDERS`."""
    for folder in FOLDERS:
        for path in sorted((root / folder).rglob("*.py")):
            name = path.relative_to(root).as_posix()
            tree = ast.parse(path.read_text(), str(path))
            for qualname, node in _functions(tree, ""):
                yield f"{name}::{qualname}", node.end_lineno - node.lineno + 1


def _functions(node: ast.AST, prefix: str) -> Iterator[tuple[str, ast.AST]]:
    """The functions inside ``node`` (methods and nested ones too) with dotted names."""
    for child in ast.iter_child_nodes(node):
        if isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            qualname = f"{prefix}{child.name}"
            if not isinstance(child, ast.ClassDef):
                yield qualname, child
            yield from _functions(child, qualname + ".")
        else:
            yield from _functions(child, prefix)


def violations(root: Path = ROOT) -> list[str]:
    """Every breach of the rule, one line each (empty: the rule holds)."""
    lengths = dict(function_lengths(root))
    out = [f"{name}: {n} lines (at most {MAX_FUNCTION_LINES}; cut it at its phases, or "
           f"list it in tools/code_rules.py ALLOWED with the reason)"
           for name, n in lengths.items() if n > MAX_FUNCTION_LINES and name not in ALLOWED]
    out += [f"{name}: listed in tools/code_rules.py ALLOWED but "
            + (f"{lengths[name]} lines now: remove the entry" if name in lengths
               else "no longer exists: remove the entry")
            for name in ALLOWED if lengths.get(name, 0) <= MAX_FUNCTION_LINES]
    return out


#: The packages whose modules are numerical kernels, but for :data:`TRANSLATORS` and
#: :data:`PENDING` (paths relative to ``railvib_hpc/``).
KERNEL_PACKAGES = ("fem", "mesh", "model", "modal", "mbs", "transient", "reconstruct", "assess")
#: Modules of :data:`KERNEL_PACKAGES` that read the case by design, with why.
TRANSLATORS: dict[str, str] = {
    **{f"{pkg}/stage.py": "a stage: builds the problem object from the case"
       for pkg in ("mesh", "modal", "mbs", "transient", "reconstruct", "assess")},
    "mesh/layout.py": "turns the case's geometry keys into the mesh layout",
    "mesh/building.py": "turns the case's [building] into the building's plan",
    "mesh/turn.py": "turns the case's rotation keys into the turned building and soil",
    "mesh/interfaces.py": "turns the case's elastic interfaces into their planes",
    "mesh/dispersion_check.py": "checks the case's mesh sizes against its wavelengths",
    "mesh/checks.py": "the mesh check's warnings (split from mesh/stage.py): the case's "
                      "wavelength band and elements per wavelength",
    "modal/refusals.py": "what the modal path's stages refuse of a case (their "
                         "Stage.refuse): its track, track ends, damping and boundaries",
    "mbs/case_vehicle.py": "the case -> vehicle and passage translation",
    "transient/surface_case.py": "the case's [load] -> the moving surface load and its "
                                 "passage (track.count = 0), as mbs/case_vehicle.py the train",
    "transient/engines.py": "the transient stage's setup of its engines (split from "
                            "transient/stage.py): reads the case's transient, damping and "
                            "boundary keys",
    "transient/run_setup.py": "the transient stage's run setup (split from "
                              "transient/stage.py): the case's passage, step, outputs and "
                              "probes -> the typed run the loop steps",
    "mbs/damping_model.py": "the case's modal.damping and mbs.damping_* overrides",
    "transient/spectral_refusals.py": "what the transient stage refuses of a spectral soil "
                                      "(its Stage.refuse): building, track, engine, "
                                      "boundaries",
    "transient/spectral_case.py": "the case -> the spectral soil's run (split from "
                                  "transient/stage.py): reads the case's load, damping, "
                                  "boundary and output keys",
    "assess/thesis.py": "the thesis comparison: describes the case's mesh, vehicle and "
                        "geometry next to the thesis's tables",
}
#: Kernel modules not yet converted to the problem object, with why (to go).
PENDING: dict[str, str] = {}


def kernel_modules(root: Path = ROOT, translators: Mapping[str, str] = TRANSLATORS
                   ) -> list[str]:
    """The modules of :data:`KERNEL_PACKAGES` (relative to ``railvib_hpc/``) that are not
    ``translators``: those the case rule covers (:data:`PENDING` among them)."""
    out = []
    for pkg in KERNEL_PACKAGES:
        for path in sorted((root / "railvib_hpc" / pkg).rglob("*.py")):
            name = path.relative_to(root / "railvib_hpc").as_posix()
            if name not in translators:
                out.append(name)
    return out


def case_uses(tree: ast.AST) -> list[str]:
    """Where a module's syntax tree takes the case: parameters named ``case`` and imports
    from ``railvib_hpc.config``, one line each."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda):
            a = node.args
            if any(arg.arg == "case" for arg in (*a.posonlyargs, *a.args, *a.kwonlyargs)):
                name = getattr(node, "name", "<lambda>")
                out.append(f"line {node.lineno}: {name}() takes a parameter named case")
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if (module == "railvib_hpc.config" if node.level == 0 else
                    module.split(".")[-1] == "config"
                    or (not module and any(a.name == "config" for a in node.names))):
                names = ", ".join(alias.name for alias in node.names)
                out.append(f"line {node.lineno}: imports {names} from the case module")
        elif isinstance(node, ast.Import):
            out += [f"line {node.lineno}: imports {alias.name}" for alias in node.names
                    if alias.name == "railvib_hpc.config"]
    return out


def case_violations(root: Path = ROOT, translators: Mapping[str, str] = TRANSLATORS,
                    pending: Mapping[str, str] = PENDING) -> list[str]:
    """Every breach of the case rule, one line each (empty: the rule holds)."""
    out = []
    for name in kernel_modules(root, translators):
        path = root / "railvib_hpc" / name
        uses = case_uses(ast.parse(path.read_text(), str(path)))
        if name in pending:
            if not uses:
                out.append(f"railvib_hpc/{name}: listed in tools/code_rules.py PENDING but "
                           "it no longer takes the case: remove the entry")
            continue
        out += [f"railvib_hpc/{name}: {use} (a kernel takes the problem object, "
                "railvib_hpc/problem.py, and arrays; or list a translator in "
                "tools/code_rules.py TRANSLATORS with the reason)" for use in uses]
    out += [f"railvib_hpc/{name}: listed in tools/code_rules.py TRANSLATORS or PENDING but "
            "no such module: remove the entry"
            for name in (*translators, *pending) if not (root / "railvib_hpc" / name).exists()]
    return out


#: The one home of the package's file names (relative to ``railvib_hpc/``).
FILE_NAMES_MODULE = "io/files.py"


def file_names(root: Path = ROOT) -> set[str]:
    """The file names that :data:`FILE_NAMES_MODULE` defines: its module-level string
    constants that end in a file extension (``"modes.h5"``, ``"run.json"``, ...)."""
    tree = ast.parse((root / "railvib_hpc" / FILE_NAMES_MODULE).read_text())
    out = set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and \
                isinstance(node.value.value, str) and "." in node.value.value.strip("."):
            out.add(node.value.value)
    return out


def _docstrings(tree: ast.AST) -> set[int]:
    """The ids of the docstring constants of a module, its classes and functions."""
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                out.add(id(body[0].value))
    return out


def file_name_violations(root: Path = ROOT) -> list[str]:
    """Every string literal of ``railvib_hpc`` outside :data:`FILE_NAMES_MODULE` that is one
    of its file names, one line each (empty: the rule holds)."""
    names = file_names(root)
    out = []
    for path in sorted((root / "railvib_hpc").rglob("*.py")):
        rel = path.relative_to(root / "railvib_hpc").as_posix()
        if rel == FILE_NAMES_MODULE:
            continue
        tree = ast.parse(path.read_text(), str(path))
        skip = _docstrings(tree)
        out += [f"railvib_hpc/{rel}: line {node.lineno}: the file name {node.value!r} "
                f"(use its constant from railvib_hpc/{FILE_NAMES_MODULE})"
                for node in ast.walk(tree)
                if isinstance(node, ast.Constant) and isinstance(node.value, str)
                and node.value in names and id(node) not in skip]
    return out


#: Longest module of ``railvib_hpc`` [lines].
MAX_MODULE_LINES = 1000
#: Modules allowed over :data:`MAX_MODULE_LINES` for now, with why (to go).
LONG_MODULES: dict[str, str] = {}


def module_length_violations(root: Path = ROOT,
                             allowed: Mapping[str, str] = LONG_MODULES) -> list[str]:
    """Every module of ``railvib_hpc`` over :data:`MAX_MODULE_LINES` lines not in
    ``allowed``, and every entry of ``allowed`` no longer needed."""
    out = []
    for path in sorted((root / "railvib_hpc").rglob("*.py")):
        name = path.relative_to(root / "railvib_hpc").as_posix()
        n = len(path.read_text().splitlines())
        if n > MAX_MODULE_LINES and name not in allowed:
            out.append(f"railvib_hpc/{name}: {n} lines (at most {MAX_MODULE_LINES}: split it "
                       "by what its parts do)")
        elif n <= MAX_MODULE_LINES and name in allowed:
            out.append(f"railvib_hpc/{name}: listed in tools/code_rules.py LONG_MODULES but it "
                       f"has {n} lines: remove the entry")
    out += [f"railvib_hpc/{name}: listed in tools/code_rules.py LONG_MODULES but no such "
            "module: remove the entry"
            for name in allowed if not (root / "railvib_hpc" / name).exists()]
    return out


#: An internal ticket cited by number ("issue 28", "Issues 26 and 28", "issue #12").
TICKET = re.compile(r"\bissues?\s+#?\d+", re.IGNORECASE)
#: The text the ticket rule reads: the package's sources, the docs and the README.
TICKET_SUFFIXES = (".py", ".md", ".rst", ".txt", ".toml")


def ticket_violations(root: Path = ROOT) -> list[str]:
    """Every line of ``railvib_hpc/``, ``docs/`` and ``README.md`` that cites a ticket by
    number (:data:`TICKET`)."""
    paths = [*sorted((root / "railvib_hpc").rglob("*.py")),
             *sorted(p for p in (root / "docs").rglob("*") if p.suffix in TICKET_SUFFIXES),
             root / "README.md"]
    out = []
    for path in paths:
        if not path.is_file():
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            for match in TICKET.finditer(line):
                out.append(f"{path.relative_to(root).as_posix()}: line {number}: "
                           f"{match.group(0)!r} (cite the literature, the thesis or the reason)")
    return out


#: The modules below the assessment (relative to ``railvib_hpc/``): the schema and the
#: standards' declarations it takes its choices from.
BELOW_ASSESS = ("schema", "standards_registry.py")


def _imported_modules(path: Path, package: str) -> Iterator[tuple[int, str]]:
    """``(line, module)`` of every import of ``path`` (module ``package.<stem>``), relative
    ones resolved, function-level and ``TYPE_CHECKING`` ones included."""
    parts = package.split(".")
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            yield from ((node.lineno, a.name) for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(parts[:len(parts) - node.level + 1] + ([base] if base else []))
            yield node.lineno, base
            yield from ((node.lineno, f"{base}.{a.name}") for a in node.names)


def schema_import_violations(root: Path = ROOT) -> list[str]:
    """Every import of ``railvib_hpc.assess`` by a module of :data:`BELOW_ASSESS`."""
    out = []
    for below in BELOW_ASSESS:
        start = root / "railvib_hpc" / below
        paths = sorted(start.rglob("*.py")) if start.is_dir() else [start]
        for path in paths:
            if not path.is_file():
                continue
            rel = path.relative_to(root).with_suffix("")
            package = ".".join(rel.parts if path.name == "__init__.py" else rel.parts[:-1])
            package = package.removesuffix(".__init__")
            seen = set()
            for line, module in _imported_modules(path, package):
                if (module == "railvib_hpc.assess" or module.startswith("railvib_hpc.assess.")
                        ) and line not in seen:
                    seen.add(line)
                    out.append(f"{path.relative_to(root).as_posix()}: line {line}: imports "
                               f"{module} (the schema sits below the assessment: declare "
                               "what it needs in railvib_hpc/standards_registry.py)")
    return out


def main() -> int:
    """Print the breaches of the rules; 1 if there are any."""
    found = (violations() + case_violations() + file_name_violations()
             + module_length_violations() + ticket_violations() + schema_import_violations())
    for line in found:
        print(line, file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
