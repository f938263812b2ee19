"""The stage rules of ``make lint``: a stage works through its context, and the runner owns
the graph of the stages.

A stage module (``railvib_hpc/<package>/stage.py``) declares its ``STAGE``
(:class:`~railvib_hpc.io.stage_protocol.Stage`) and works through the context its
``compute`` gets: the reuse verdict and its message, provenance, the lock and ``run.json``
belong to :mod:`railvib_hpc.io.stage_protocol` and its runner. The rules fail when a module
of a stage's package

* imports one of :data:`FORBIDDEN` itself, or the modules that hold them as a whole;
* imports another stage's own module (``<other package>.stage``, or a name from it): the
  products of the stages it needs come to it through its context
  (``ctx.input("mesh")``), their case keys through its products' rows (``extends``), and
  what they share lives in the modules below the stages (``io``, ``mesh.checks``,
  ``modal.refusals``, ...);
* builds a :class:`~railvib_hpc.io.stage_protocol.StageContext` (the runner builds it and
  it is passed on, never rebuilt).

The rules cover every module of a stage's package, not only its ``stage.py``: a helper
split out of a stage (``mbs/damping_model.py``, ``mbs/case_vehicle.py``, ...) goes
through a :class:`~railvib_hpc.io.stage_protocol.StageContext` too.

Usage::

    python tools/stage_rules.py      # lists the offenders and exits with 1, if any

``tests/test_stage_protocol.py`` checks the same in the quick tier.
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The names of the reuse, provenance, lock and run-record layer a stage may not import
#: (``require_inputs``: the upstream check is ``ctx.require``).
FORBIDDEN = frozenset({"examine", "forget", "provenance", "require_inputs", "output_lock",
                       "acquire_lock", "release_lock", "record_stage", "append_entry"})
#: The modules that hold them (importing one whole would reach them too): ``forget`` is in
#: ``digests``, the reuse and provenance in ``provenance``, the locks in ``locks``.
LAYER_MODULES = frozenset({"digests", "provenance", "locks", "run_record"})


def stage_modules(root: Path = ROOT) -> list[Path]:
    """Every module of a stage's package: the ``railvib_hpc/<package>/`` that holds a
    ``stage.py``, its subfolders included."""
    return sorted(path for stage in (root / "railvib_hpc").glob("*/stage.py")
                  for path in stage.parent.rglob("*.py"))


def _stage_module(module: str, level: int, package: str) -> str | None:
    """The stage package whose ``stage`` module an import names (``..mesh.stage``,
    ``railvib_hpc.mesh.stage``), if any; ``package``: the importing module's package
    (``railvib_hpc.modal``), for relative imports."""
    if level:
        base = package.split(".")
        base = base[:len(base) - (level - 1)] if level > 1 else base
        module = ".".join([*base, module] if module else base)
    parts = module.split(".")
    if len(parts) == 3 and parts[0] == "railvib_hpc" and parts[2] == "stage":
        return parts[1]
    return None


def _graph_offences(tree: ast.AST, package: str) -> list[str]:
    """Imports of another stage's module and contexts built (``package``: the module's)."""
    own = package.split(".")[1] if package.count(".") >= 1 else ""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            other = _stage_module(node.module or "", node.level, package)
            names = [a.name for a in node.names]
            if other is None and "stage" in names:         # from ..mesh import stage
                other = _stage_module(f"{node.module}.stage" if node.module else "stage",
                                      node.level, package)
            if other is not None and other != own:
                out.append(f"line {node.lineno}: imports railvib_hpc.{other}.stage, the "
                           f"{other} stage's own module (what a stage needs comes through "
                           "its context, ctx.input)")
        elif isinstance(node, ast.Import):
            for alias in node.names:
                other = _stage_module(alias.name, 0, package)
                if other is not None and other != own:
                    out.append(f"line {node.lineno}: imports railvib_hpc.{other}.stage, the "
                               f"{other} stage's own module (what a stage needs comes through "
                               "its context, ctx.input)")
        elif isinstance(node, ast.Call) and getattr(node.func, "id", getattr(
                node.func, "attr", None)) == "StageContext":
            out.append(f"line {node.lineno}: builds a StageContext (the runner builds it; a "
                       "stage passes the one it got)")
    return out


def _offences(tree: ast.AST) -> list[str]:
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = (node.module or "").rsplit(".", 1)[-1]
            for alias in node.names:
                if module in LAYER_MODULES and alias.name in FORBIDDEN:
                    out.append(f"line {node.lineno}: imports {alias.name} from {node.module}")
                elif alias.name in LAYER_MODULES:
                    out.append(f"line {node.lineno}: imports the module {alias.name}")
        elif isinstance(node, ast.Import):
            out += [f"line {node.lineno}: imports the module {alias.name}"
                    for alias in node.names if alias.name.rsplit(".", 1)[-1] in LAYER_MODULES]
    return out


def violations(root: Path = ROOT) -> list[str]:
    """Every breach of the rule, one line each (empty: the rule holds)."""
    out = []
    for path in stage_modules(root):
        name = path.relative_to(root).as_posix()
        tree = ast.parse(path.read_text(), str(path))
        for offence in _offences(tree):
            out.append(f"{name}: {offence} (a stage uses its context: ctx.reuse, "
                       "ctx.require, ctx.provenance, ctx.discard; the runner holds the lock "
                       "and writes run.json)")
        package = ".".join(path.relative_to(root).with_suffix("").parts[:-1])
        out += [f"{name}: {offence}" for offence in _graph_offences(tree, package)]
    return out


def main() -> int:
    """Print the breaches of the rule; 1 if there are any."""
    found = violations()
    for line in found:
        print(line, file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
