"""The coarse ``run`` and ``transient`` give what they gave before the stage protocol (issue 27).

``tests/data/golden_run.json`` was recorded with ``tools/golden_run.py`` on 1 and 2 ranks
before the stages were restructured: the provenance of every product (format version,
stage, inputs digest, upstream files), every probe's peak velocity and acceleration, and
which files a rerun (and a rerun after ``output.dt`` changed) reuses or recomputes.

Re-recorded since only for new case keys of issues 28, 29 and 30 (``transient.engine`` and
the other engine keys, ``track.ends``, ``track.end_*``, ``[uncertainty]``,
``boundary.pml_*``), in six commits (3089d63, 5b469b6, eff6b3b, ed2b99b, 0e45d61, and the
issue-29 one, which moved only the two whole-case ``assessment.json`` digests: peaks within
6e-12; some re-recorded one rank count at a time).
Against the first record (commit 100b185, before any change of issue 27) the current one
differs, on 1 and on 2 ranks, in exactly five inputs digests: those of the products whose
inputs include ``[transient]`` or the whole case (``transient.h5``, the transient
``fields.h5`` and ``probes.h5``, and both ``assessment.json``). Every other digest (mesh.h5,
modes.h5, static.h5, mbs.h5, fields.h5, probes.h5 of ``run``), every reuse verdict and
every format version is unchanged, and the probe peaks agree within 1.8e-9 relative
(``run``; ``transient`` within 3.6e-12): the purification of issue 26 leaves the Ritz pairs
already within tolerance as they are (eigenvalues within 6.7e-13).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import golden_run  # noqa: E402

GOLDEN = ROOT / "tests" / "data" / "golden_run.json"
comm = MPI.COMM_WORLD


def _compare(folder: Path) -> None:
    got = golden_run.record(folder)
    if comm.rank == 0:
        expected = json.loads(GOLDEN.read_text())[str(comm.size)]
        assert golden_run.differences(expected, got) == []
    comm.Barrier()


def test_differences_are_found():
    """The comparison itself notices a changed digest, peak and reuse verdict."""
    doc = json.loads(GOLDEN.read_text())["1"]
    assert golden_run.differences(doc, doc) == []
    bent = json.loads(json.dumps(doc))
    bent["run"]["provenance"]["modes.h5"]["inputs_sha256"] = "0" * 64
    probe = sorted(bent["run"]["peaks"])[0]
    bent["run"]["peaks"][probe][0] *= 1 + 10 * golden_run.PEAK_RTOL
    bent["transient"]["rerun"] = bent["transient"]["rerun"][1:]
    bad = golden_run.differences(doc, bent)
    assert len(bad) == 3 and "modes.h5" in bad[0] and probe in bad[1] and "rerun" in bad[2]


@pytest.mark.slow
def test_coarse_run_unchanged_on_one_rank(shared_tmp):
    _compare(shared_tmp)


@pytest.mark.slow
@pytest.mark.mpi
def test_coarse_run_unchanged_on_n_ranks(shared_tmp):
    _compare(shared_tmp)
