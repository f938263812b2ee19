"""The package's architecture in numbers: string switches on engine and boundary names,
stage-to-stage imports, stage-context rebuilds, the largest modules and import cycles.

The numbers a restructuring is measured by (before and after, with this one script):

* **string switches**: comparisons, membership tests, dictionary keys and ``match`` cases
  whose string literal is the name of a time-domain engine (``direct``, ``explicit``,
  ``imex``) or of a boundary kind (``fixed``, ``roller``, ``free``, ``absorbing``,
  ``caughey``, ``pml``), per file; the files that name each engine or kind in any string
  literal (the places a new one would have to be added by hand);
* **stage-to-stage imports**: imports of another stage's own ``<stage>.stage`` module (the
  stage that builds a product another stage needs), and all import statements (module
  level, inside functions or under ``TYPE_CHECKING``) in one stage package (``mesh``,
  ``modal``, ``mbs``, ``reconstruct``, ``transient``, ``assess``) of a module of another;
* **context rebuilds**: calls ``StageContext(...)`` outside ``io/stage_protocol.py``;
* **the largest modules** (lines);
* **import cycles** between modules, counting every import (``TYPE_CHECKING`` ones and
  imports inside functions too): the strongly connected components of the import graph.

Usage::

    python tools/architecture_metrics.py [--root railvib_hpc] [--top 8]
"""

from __future__ import annotations

import argparse
import ast
import sys
from collections import defaultdict
from pathlib import Path

#: The time-domain engines' names (``transient.engine``) in the tree being measured.
ENGINES = ("direct", "explicit", "imex")
#: The boundary kinds (``boundary.<face>``) in the tree being measured.
BOUNDARY_KINDS = ("fixed", "roller", "free", "absorbing", "caughey", "pml")
#: The pipeline's stage packages.
STAGE_PACKAGES = ("mesh", "modal", "mbs", "reconstruct", "transient", "assess")


def _strings(node: ast.AST) -> list[str]:
    """The string constants of ``node`` itself or of a tuple/list/set literal."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return [node.value]
    if isinstance(node, ast.Tuple | ast.List | ast.Set):
        return [s for e in node.elts for s in _strings(e)]
    return []


def switches(tree: ast.AST, names: tuple[str, ...]) -> int:
    """How many comparisons, dictionary literals and match cases of ``tree`` switch on one
    of ``names``."""
    count = 0
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            ops = [node.left, *node.comparators]
            if any(set(_strings(o)) & set(names) for o in ops):
                count += 1
        elif isinstance(node, ast.Dict):
            keys = [s for k in node.keys if k is not None for s in _strings(k)]
            if len(set(keys) & set(names)) >= 2:
                count += 1
        elif isinstance(node, ast.match_case) and set(_literals(node.pattern)) & set(names):
            count += 1
    return count


def _literals(pattern: ast.AST) -> list[str]:
    return [n.value.value for n in ast.walk(pattern)
            if isinstance(n, ast.MatchValue) and isinstance(n.value, ast.Constant)
            and isinstance(n.value.value, str)]


def literal_files(tree: ast.AST, name: str) -> bool:
    """Whether ``tree`` has ``name`` as a string literal (not in a docstring)."""
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, ast.Module | ast.FunctionDef | ast.ClassDef
                                | ast.AsyncFunctionDef)
                  and n.body and isinstance(n.body[0], ast.Expr)
                  and isinstance(n.body[0].value, ast.Constant)}
    return any(isinstance(n, ast.Constant) and n.value == name and id(n) not in docstrings
               for n in ast.walk(tree))


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports(tree: ast.AST, module: str, is_package: bool) -> list[str]:
    """Every module ``module`` imports (absolute names; relative imports resolved)."""
    base = module.split(".") if is_package else module.split(".")[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                pkg = base[:len(base) - node.level + 1]
                target = ".".join(pkg + ([node.module] if node.module else []))
            else:
                target = node.module or ""
            out.append(target)
            out += [f"{target}.{a.name}" for a in node.names]
    return out


def stage_of(module: str, root_name: str) -> str | None:
    parts = module.split(".")
    if len(parts) >= 2 and parts[0] == root_name and parts[1] in STAGE_PACKAGES:
        return parts[1]
    return None


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v: str) -> None:
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def measure(root: Path, top: int) -> str:
    files = sorted(root.rglob("*.py"))
    trees = {f: ast.parse(f.read_text(), str(f)) for f in files}
    names = {f: module_name(f, root) for f in files}
    known = set(names.values())
    lines = [f"# Architecture of {root}", ""]

    for title, kinds in (("engine", ENGINES), ("boundary kind", BOUNDARY_KINDS)):
        per_file = {f: switches(t, kinds) for f, t in trees.items()}
        hit = {f: n for f, n in per_file.items() if n}
        lines.append(f"String switches on {title} names: {sum(hit.values())} in "
                     f"{len(hit)} files")
        for f, n in sorted(hit.items(), key=lambda kv: -kv[1]):
            lines.append(f"  {n:3d}  {f.relative_to(root.parent)}")
        for k in kinds:
            where = [f for f, t in trees.items() if literal_files(t, k)]
            lines.append(f"  files naming {k!r} in a string literal: {len(where)}")
        lines.append("")

    graph: dict[str, set[str]] = defaultdict(set)
    stage_imports = []
    for f, t in trees.items():
        mod = names[f]
        for target in imports(t, mod, f.name == "__init__.py"):
            while target and target not in known:
                target = target.rpartition(".")[0]
            if not target or target == mod:
                continue
            graph[mod].add(target)
            a, b = stage_of(mod, root.name), stage_of(target, root.name)
            if a and b and a != b:
                stage_imports.append((mod, target))
    builders = [(a, b) for a, b in stage_imports if b.endswith(".stage")]
    lines.append(f"Imports of another stage's own module (its product builder, "
                 f"`<stage>.stage`): {len(builders)} statements")
    for (a, b) in sorted(set(builders)):
        lines.append(f"  {a} -> {b}  (x{builders.count((a, b))})")
    unique = sorted(set(stage_imports))
    lines.append(f"Imports between stage packages, all: {len(stage_imports)} statements "
                 f"({len(unique)} distinct module pairs)")
    for a, b in unique:
        lines.append(f"  {a} -> {b}")
    lines.append("")

    rebuilds = []
    for f, t in trees.items():
        if f.name == "stage_protocol.py":
            continue
        for node in ast.walk(t):
            if isinstance(node, ast.Call):
                fn = node.func
                name = fn.id if isinstance(fn, ast.Name) else \
                    fn.attr if isinstance(fn, ast.Attribute) else ""
                if name == "StageContext":
                    rebuilds.append(f"{f.relative_to(root.parent)}:{node.lineno}")
    lines.append(f"StageContext built outside the runner: {len(rebuilds)}")
    lines += [f"  {r}" for r in rebuilds]
    lines.append("")

    sizes = sorted(((len(f.read_text().splitlines()), f) for f in files), reverse=True)
    over = sum(1 for n, _ in sizes if n > 1000)
    lines.append(f"Largest modules ({over} over 1000 lines):")
    lines += [f"  {n:5d}  {f.relative_to(root.parent)}" for n, f in sizes[:top]]
    lines.append("")

    # cycles between sibling modules (a package importing its own submodules is its
    # re-export, not a cycle of logic: the edges package -> its own submodule are dropped)
    sibling = {a: {b for b in bs if not b.startswith(a + ".")} for a, bs in graph.items()}
    comps = cycles(sibling)
    lines.append(f"Import cycles (every import, TYPE_CHECKING and function-level ones "
                 f"included): {len(comps)}")
    lines += [f"  {' <-> '.join(c)}" for c in comps]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", default=str(Path(__file__).resolve().parents[1]
                                              / "railvib_hpc"))
    parser.add_argument("--top", type=int, default=8)
    args = parser.parse_args(argv)
    print(measure(Path(args.root), args.top))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
