"""The function-length rule of ``make lint``: no function over 150 lines unless allowed.

A function's length is counted by its syntax tree, from its ``def`` line to its last line,
docstring and comments included (decorators not). A function that must stay longer is
listed in :data:`ALLOWED` with the reason; an entry that is no longer needed (the function
got shorter, or is gone) breaks the rule too, so that the list stays short and true.

Usage::

    python tools/code_rules.py      # lists the offenders and exits with 1, if any

``tests/test_code_rules.py`` checks the same in the quick tier.
"""

from __future__ import annotations

import ast
import sys
from collections.abc import Iterator
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


def main() -> int:
    """Print the breaches of the rule; 1 if there are any."""
    found = violations()
    for line in found:
        print(line, file=sys.stderr)
    return 1 if found else 0


if __name__ == "__main__":
    raise SystemExit(main())
