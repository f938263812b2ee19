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
def serial_refs(request):
    """The serial references of the selected N-rank tests, ``{name: folder}``: each computed
    once per session on one rank alone (``MPI.COMM_SELF``), the ranks side by side.

    A test module lists its references in ``SERIAL_REFERENCES = {name: (seconds, build)}``
    (``build(folder)`` computes one into ``folder`` on ``MPI.COMM_SELF``; ``seconds``, what
    it took on one rank, orders them). The N-rank tests used to rerun their reference on
    rank 0 after their own run while the other ranks waited at a barrier; here the
    references of every selected test that asks for this fixture are handed out longest
    first, each to the rank with the fewest seconds so far, so that N ranks compute N of
    them at a time. A reference is the same computation on any rank (one process,
    ``MPI.COMM_SELF``). A failure on any rank fails the fixture on every rank (none waits in
    a collective)."""
    import time
    import traceback

    from mpi4py import MPI

    from railvib_hpc.petsc_env import init_petsc

    comm = MPI.COMM_WORLD
    refs: dict = {}
    for item in request.session.items:
        if "serial_refs" in getattr(item, "fixturenames", ()):
            refs.update(getattr(item.module, "SERIAL_REFERENCES", {}))
    root = tempfile.mkdtemp(prefix="railvib-serial-") if comm.rank == 0 else None
    root = Path(comm.bcast(root, root=0))
    init_petsc([])                  # collective: before the ranks work alone on COMM_SELF
    load = [0.0] * comm.size
    failures, timings = [], []
    for name, (seconds, build) in sorted(refs.items(), key=lambda kv: (-kv[1][0], kv[0])):
        rank = load.index(min(load))
        load[rank] += seconds
        if rank != comm.rank or failures:
            continue
        t0 = time.perf_counter()
        try:
            build(root / name)
        except Exception:                     # re-raised below on every rank
            failures.append(f"serial reference {name} (rank {comm.rank}):\n"
                            f"{traceback.format_exc()}")
        timings.append(f"serial reference {name}: {time.perf_counter() - t0:.1f} s "
                       f"on rank {comm.rank}")
    print("\n".join(line for lines in comm.allgather(timings) for line in lines))
    failures = [f for lines in comm.allgather(failures) for f in lines]
    if failures:
        raise RuntimeError("\n".join(failures))
    yield {name: root / name for name in refs}
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(root, ignore_errors=True)


@pytest.fixture(scope="session")
def baseline_mesh():
    """The thesis baseline mesh at refinement 1 (built once per session) and its report."""
    from railvib_hpc.mesh.stage import make_mesh

    return make_mesh(load_case(BASELINE))


@pytest.fixture(scope="session")
def baseline_layout():
    from railvib_hpc.mesh.layout import build_layout

    return build_layout(load_case(BASELINE))


@pytest.fixture
def failing_contact_newton(monkeypatch):
    """``fail_at(call)``: the wheel-rail contact's Newton
    (:func:`railvib_hpc.mbs.integrate.solve_contact`) made to raise
    :class:`~railvib_hpc.errors.ContactNewtonError` at its ``call``-th call (1-based), and
    to solve as usual otherwise."""
    from railvib_hpc.errors import ContactNewtonError
    from railvib_hpc.mbs import integrate

    def fail_at(call: int) -> None:
        calls, solve = [0], integrate.solve_contact

        def failing(*args):
            calls[0] += 1
            if calls[0] == call:
                raise ContactNewtonError(50, 1e-9, 1e-15)
            return solve(*args)

        monkeypatch.setattr(integrate, "solve_contact", failing)

    return fail_at
