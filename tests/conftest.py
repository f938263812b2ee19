"""Shared fixtures. MPI-aware: ``shared_tmp`` is one folder for all ranks."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import pytest

from railvib_hpc.config import load_case

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: The fault-injection entries the pytest-xdist workers handed back
#: (tests/reliability/conftest.py: ``pytest_sessionfinish``).
WORKER_FAULT_TALLY: list[dict] = []


#: Seconds per test of an earlier pass (tools/test_weights.py writes it).
TEST_WEIGHTS = ROOT / "tests" / "data" / "test_weights.json"


@pytest.hookimpl(trylast=True)
def pytest_collection_modifyitems(config, items):
    """The test files in the order of their selected tests' recorded seconds, the longest
    first (the order within a file kept): pytest-xdist hands out whole files in this
    order (``--dist loadfile --no-loadscope-reorder``, Makefile), so a long file does not
    start last while the other workers idle (tools/test_weights.py). ``trylast``: after
    ``-m`` deselected what this pass does not run."""
    import json

    if not TEST_WEIGHTS.exists():
        return
    seconds = json.loads(TEST_WEIGHTS.read_text())
    per_file: dict[str, float] = {}
    for item in items:
        path = item.nodeid.split("::")[0]
        per_file[path] = per_file.get(path, 0.0) + seconds.get(item.nodeid, 0.0)
    items.sort(key=lambda item: -per_file[item.nodeid.split("::")[0]])


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    """pytest-xdist, on the controller: collect a finished worker's fault-injection
    entries."""
    WORKER_FAULT_TALLY.extend(getattr(node, "workeroutput", {}).get("fault_tally", []))


def pytest_terminal_summary(terminalreporter):
    """The fault-injection suite's tally of every xdist worker (in one process its own
    conftest prints it)."""
    if not WORKER_FAULT_TALLY:
        return
    import sys

    sys.path.insert(0, str(ROOT / "tests" / "reliability"))
    from faults import tally_line, write_tally

    terminalreporter.write_line(tally_line(WORKER_FAULT_TALLY))
    write_tally(WORKER_FAULT_TALLY)


@pytest.fixture
def one_line_refusal(capsys):
    """A check of a refused command: ``check(code, out, needle)`` asserts exit code 2, one
    non-blank line on stderr that contains ``needle``, no traceback, and nothing written in
    the output folder ``out``."""
    def check(code: int, out: Path, needle: str) -> None:
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if ln.strip()]
        assert code == 2, err
        assert "Traceback" not in err
        assert len(lines) == 1, err
        assert needle in lines[0], lines[0]
        assert not out.exists() or not any(out.iterdir())
    return check


@pytest.fixture
def shared_tmp():
    """A temporary folder with the same path on every MPI rank."""
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    path = tempfile.mkdtemp(prefix="railvib-test-") if comm.rank == 0 else None
    path = Path(comm.bcast(path, root=0))
    yield path
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope="session")
def baseline_mesh():
    """The thesis baseline mesh at refinement 1 (built once per session) and its report."""
    from railvib_hpc.mesh.stage import make_mesh

    return make_mesh(load_case(BASELINE))


@pytest.fixture(scope="session")
def baseline_layout():
    from railvib_hpc.mesh.layout import build_layout

    return build_layout(load_case(BASELINE))
