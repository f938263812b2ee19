"""The layer order of ``.importlinter`` holds, and ``make lint`` fails when a cycle returns.

``make lint`` runs ``lint-imports`` with the contracts of ``.importlinter``. These tests run
the same command on the package as it is (every contract kept) and on copies into which one
import is added that reintroduces a cycle this codebase once had (every one breaks a
contract, so ``make lint`` fails on it).
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LINT_IMPORTS = Path(sys.executable).with_name("lint-imports")

pytestmark = pytest.mark.skipif(not LINT_IMPORTS.exists(),
                                reason="import-linter is installed by `make setup`")


def _lint_imports(tree: Path) -> subprocess.CompletedProcess:
    """``lint-imports`` as ``make lint`` runs it, on the package under ``tree``."""
    env = {"PYTHONPATH": str(tree), "PATH": "/usr/bin:/bin"}
    return subprocess.run([str(LINT_IMPORTS), "--no-cache", "--config",
                           str(tree / ".importlinter")],
                          cwd=tree, env=env, capture_output=True, text=True, timeout=120)


def _copy(tmp_path: Path) -> Path:
    tree = tmp_path / "tree"
    shutil.copytree(ROOT / "railvib_hpc", tree / "railvib_hpc",
                    ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / ".importlinter", tree / ".importlinter")
    return tree


def test_contracts_kept(tmp_path):
    res = _lint_imports(_copy(tmp_path))
    assert res.returncode == 0, res.stdout + res.stderr
    assert "0 broken" in res.stdout


#: (module, import line): the cycles the layer work removed, each put back by one import.
CYCLES = {
    "mesh.model <-> mesh.search": ("mesh/model.py", "from .search import locate"),
    "modal.stage <-> modal.static": ("modal/static.py", "from .stage import run_modal_stage"),
    "io <-> mesh": ("io/xdmf.py", "from ..mesh.model import Mesh"),
    "fem -> mesh": ("fem/hex8.py", "from ..mesh.search import locate"),
    "schema -> config": ("schema/__init__.py", "from ..config import Case"),
    "model -> modal": ("model/factor.py", "from ..modal.block_lanczos import Progress"),
}


@pytest.mark.parametrize("name", list(CYCLES))
def test_reintroduced_cycle_breaks_a_contract(tmp_path, name):
    tree = _copy(tmp_path)
    module, line = CYCLES[name]
    path = tree / "railvib_hpc" / module
    path.write_text(path.read_text() + f"\n{line}  # noqa: E402, F401\n")
    res = _lint_imports(tree)
    assert res.returncode != 0, f"{name}: lint-imports kept every contract\n{res.stdout}"
    assert "BROKEN" in res.stdout
