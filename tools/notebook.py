"""Write a Jupyter notebook from a script in the "percent" cell format.

Usage::

    python tools/notebook.py examples/pad_stiffness.py     # writes examples/pad_stiffness.ipynb

Cells start at lines ``# %%`` (code) and ``# %% [markdown]`` (text, each line with its
``# `` prefix removed). The notebook holds no outputs, so the script is the one source and
``tests/test_examples.py`` checks that the committed notebook is the one this writes.
No Jupyter package is needed (nbformat 4 is plain JSON).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path


def cells(source: str) -> list[dict]:
    """The notebook cells of a percent-format script."""
    out: list[dict] = []
    kind, lines = None, []

    def flush() -> None:
        while lines and not lines[-1].strip():
            lines.pop()
        if kind is None or not lines:
            return
        text = [ln[2:] if ln.startswith("# ") else ln.lstrip("#") for ln in lines] \
            if kind == "markdown" else lines
        body = [ln + "\n" for ln in text[:-1]] + [text[-1]]
        cell = {"cell_type": kind, "metadata": {}, "source": body}
        if kind == "code":
            cell.update(execution_count=None, outputs=[])
        out.append(cell)

    for line in source.splitlines():
        if line.startswith("# %%"):
            flush()
            kind, lines = ("markdown" if "[markdown]" in line else "code"), []
        elif kind is not None and (lines or line.strip()):
            lines.append(line)
    flush()
    return out


def notebook(source: str) -> str:
    """The ``.ipynb`` text (nbformat 4) of a percent-format script."""
    nb = {"cells": cells(source),
          "metadata": {"kernelspec": {"display_name": "Python 3", "language": "python",
                                      "name": "python3"},
                       "language_info": {"name": "python"}},
          "nbformat": 4, "nbformat_minor": 5}
    for i, cell in enumerate(nb["cells"]):
        cell["id"] = f"cell-{i}"
    return json.dumps(nb, indent=1, ensure_ascii=False) + "\n"


def main(argv: list[str]) -> int:
    for name in argv or ["examples/pad_stiffness.py"]:
        script = Path(name)
        target = script.with_suffix(".ipynb")
        target.write_text(notebook(script.read_text()))
        print(f"wrote {target}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
