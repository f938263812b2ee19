"""The red team: ``--out docs`` wrote about 20 result files into the project's own docs/
without a word. railvib now refuses, before anything is written, an output folder inside
its own source tree (the package, the checkout's root and project folders) or one that
holds files of railvib's names that railvib did not write (:mod:`railvib_hpc.io.out_folder`);
a new, empty or railvib-made folder, or one with other files beside (the case file), is
fine."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from faults import BASELINE
from mpi4py import MPI

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.io.out_folder import (
    PACKAGE,
    OutputFolderError,
    checkout_root,
    output_folder_problem,
)

B = str(BASELINE)
ROOT = Path(__file__).resolve().parents[2]
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=20", "--set",
          "output.dt=0.01"]


def _tree(folder: Path) -> dict[str, float]:
    return {str(p): p.stat().st_mtime for p in folder.rglob("*")}


def _refused(tally, fault: str, argv: list[str], capsys, needle: str) -> str:
    code = run(argv)
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    ok = code == 2 and len(lines) == 1 and "Traceback" not in err
    tally.add(fault, "clear error" if ok else "silent wrong" if code == 0 else "unclear",
              lines[0] if lines else "")
    assert ok, (code, err)
    assert needle in lines[0], lines[0]
    return lines[0]


@pytest.mark.skipif(checkout_root() is None, reason="not a source checkout")
@pytest.mark.parametrize("command, out, needle", [
    (["transient"], ROOT / "docs", "is inside railvib's own project folder docs/"),
    (["run"], ROOT / "jobs" / "new", "is inside railvib's own project folder jobs/"),
    (["mesh"], ROOT, "is railvib's own source checkout"),
    (["mesh"], PACKAGE / "results", "is inside railvib's own package folder"),
    (["study", "speed"], ROOT / "docs", "is inside railvib's own project folder docs/"),
])
def test_the_projects_own_folders_are_refused(command, out, needle, tally, capsys):
    before = _tree(ROOT / "docs"), _tree(ROOT / "jobs")
    _refused(tally, f"--out {out.relative_to(ROOT.parent)} ({command[-1]})",
             [*command, B, *COARSE, "--out", str(out)], capsys, needle)
    assert (_tree(ROOT / "docs"), _tree(ROOT / "jobs")) == before     # nothing written
    assert not (ROOT / "jobs" / "new").exists() and not (PACKAGE / "results").exists()
    assert not (ROOT / ".railvib").exists()


def test_the_study_list_writes_nothing_and_is_allowed(capsys):
    assert run(["study", "speed", B, "--list", "--out", str(ROOT / "docs")]) == 0
    assert "speed study" in capsys.readouterr().out and not (ROOT / "docs" / "speed").exists()


def test_someone_elses_files_of_railvibs_names_are_refused(tmp_path, tally, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "report.md").write_text("my own notes\n")
    (out / "mesh.msh").write_text("my mesh\n")
    _refused(tally, "--out a folder with someone else's report.md, mesh.msh",
             ["mesh", B, *COARSE, "--out", str(out)], capsys,
             f"output folder {out} holds mesh.msh, report.md, which railvib did not write "
             "(no .railvib/ record in it)")
    assert (out / "report.md").read_text() == "my own notes\n"
    assert sorted(os.listdir(out)) == ["mesh.msh", "report.md"]


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one rank")
def test_the_api_refuses_too(tmp_path):
    from railvib_hpc.api import Pipeline

    pipe = Pipeline(load_case(BASELINE), ROOT / "docs", MPI.COMM_SELF, quiet=True)
    with pytest.raises(OutputFolderError, match="inside railvib's own project folder docs/"):
        pipe.stage("mesh")


def test_folders_a_user_expects_to_work(tmp_path):
    assert output_folder_problem(tmp_path / "new") is None                 # new
    assert output_folder_problem(tmp_path) is None                         # empty
    (tmp_path / "case.toml").write_text("[case]\n")                        # the case beside
    (tmp_path / "notes.txt").write_text("x\n")
    assert output_folder_problem(tmp_path) is None
    made = tmp_path / "made"                                # railvib's own earlier results
    (made / ".railvib").mkdir(parents=True)
    (made / "report.md").write_text("# report\n")
    assert output_folder_problem(made) is None
    if checkout_root() is not None:
        assert output_folder_problem(ROOT / "results" / "x") is None       # the default


@pytest.mark.mpi
@pytest.mark.skipif(checkout_root() is None, reason="not a source checkout")
def test_the_refusals_are_collective(capsys):
    """On every rank the same exit code, no rank left waiting, nothing written: the
    project's docs/ as --out, and (validated on rank 0, broadcast) a load path through
    the building."""
    comm = MPI.COMM_WORLD
    never = ROOT / "results" / "never-written"
    codes = [run(["transient", B, *COARSE, "--out", str(ROOT / "docs")]),
             run(["transient", B, *COARSE, "--set", "track.count=0", "--set",
                  "load.force=1e5", "--set", "load.y=-13", "--out", str(never)])]
    assert codes == [2, 2] and comm.allgather(codes) == [codes] * comm.size
    err = capsys.readouterr().err
    if comm.rank == 0:
        assert "is inside railvib's own project folder docs/" in err
        assert "load.y = -13.0: the load's path y = -13 m runs through the building's" in err
    assert not never.exists() and not (ROOT / "docs" / ".railvib").exists()
