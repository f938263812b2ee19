"""The examples run: ``examples/pad_stiffness.py`` as a script, then its notebook cell by
cell (no Jupyter needed), and the notebook is the one generated from the script."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "examples" / "pad_stiffness.py"
NOTEBOOK = SCRIPT.with_suffix(".ipynb")

#: Executes the code cells of a notebook in order in one namespace, like a kernel would.
RUNNER = """
import json, sys
cells = json.load(open(sys.argv[1]))["cells"]
namespace = {"__name__": "__main__"}
for i, cell in enumerate(cells):
    if cell["cell_type"] == "code":
        exec(compile("".join(cell["source"]), f"<cell {i}>", "exec"), namespace)
print("reused:", [r["reused"] for r in namespace["rows"]])
"""


def _run(cmd: list[str], out: Path) -> str:
    env = {**os.environ, "RAILVIB_EXAMPLE_OUT": str(out)}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, cwd=ROOT,
                          timeout=600)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    return proc.stdout


def _table(text: str) -> list[str]:
    lines = text.splitlines()
    start = next(i for i, ln in enumerate(lines) if ln.lstrip().startswith("pads.kz [N/m]"))
    return lines[start:start + 4]


def test_notebook_is_generated_from_the_script():
    sys.path.insert(0, str(ROOT / "tools"))
    try:
        from notebook import notebook
    finally:
        sys.path.remove(str(ROOT / "tools"))
    assert NOTEBOOK.read_text() == notebook(SCRIPT.read_text()), \
        "run `python tools/notebook.py examples/pad_stiffness.py`"
    cells = json.loads(NOTEBOOK.read_text())["cells"]
    assert {c["cell_type"] for c in cells} == {"markdown", "code"}
    assert all(not c.get("outputs") for c in cells if c["cell_type"] == "code")


@pytest.mark.slow
def test_pad_stiffness_script_then_notebook(tmp_path):
    """The script computes every variant; the notebook runs next in the same folder and
    reuses every stage's files (as a user re-running it would), assessing again."""
    script = _run([sys.executable, str(SCRIPT)], tmp_path)
    table = _table(script)
    rows = [ln.split() for ln in table[1:]]
    assert [float(r[0]) for r in rows] == [2.65e8, 1e9, 7e9]
    deflection = [float(r[2]) for r in rows]
    assert deflection[0] > deflection[1] > deflection[2] > 0    # softer pads: more deflection
    assert all(float(r[3]) > 7.0 for r in rows)                 # above the 7.69 kN static load
    assert "pads.kz = 2.65e+08 N/m: every probe passes" in script
    assert "report:" in script and (tmp_path / "kz_2.65e+08" / "report.html").is_file()
    record = json.loads((tmp_path / "kz_2.65e+08" / "run.json").read_text())
    assert [c["stage"] for c in record["calls"]] == ["mesh", "modal", "mbs", "reconstruct",
                                                     "assess"]

    notebook = _run([sys.executable, "-c", RUNNER, str(NOTEBOOK)], tmp_path)
    assert _table(notebook) == table
    assert "reused: [True, True, True]" in notebook
