"""Partial meshes (issue 16, item 6): ``mesh.file`` with any subset of the parts.

A plain soil column (the first thing an engineer verifies a solver with): ``railvib modal``
runs on it and gives the analytic column of benchmarks.md; the stages that need rails,
sleepers or pads say so in one line. A track without the building runs the whole pipeline.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from fem_analytic import bar_fixed_free_discrete, bar_fixed_free_frequency
from fem_tools import frequency_rtol
from modal_cases import column_mesh, to_scipy, write_msh
from mpi4py import MPI

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.problem import Problem

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
H, NZ = 5.8, 32
E, NU, RHO = 200e6, 0.2, 1850.0                          # the thesis's subgrade
C_P = np.sqrt(E * (1 - NU) / ((1 + NU) * (1 - 2 * NU)) / RHO)    # 346.58 m/s
comm = MPI.COMM_WORLD


@pytest.fixture
def column_msh(shared_tmp):
    """A 0.5 x 0.5 x 5.8 m column of 32 subgrade hexahedra, no node sets, no other part."""
    path = shared_tmp / "column.msh"
    if comm.rank == 0:
        write_msh(column_mesh(NZ, H, 0.5), path)
    comm.Barrier()
    return path


def _args(msh, out, *extra):
    return ["modal", str(BASELINE), "--set", f"mesh.file='{msh}'", "--set", "modal.n_modes=4",
            "--out", str(out), *extra]


def test_soil_column_modal_against_the_analytic_column(column_msh, shared_tmp, capsys):
    """Node sets derived as the generator defines them (bottom fixed, rollers on the
    sides): with one element across, only u_z is free, the constrained P-wave column,
    f_n = (2n - 1) c_P / (4H) = 14.939 Hz, ... (benchmarks.md). The FE frequencies equal the
    exact discrete ones to round-off and the continuum ones to (q h)^2 / 24 from above."""
    out = shared_tmp / "column"
    assert run(_args(column_msh, out)) == 0
    printed = capsys.readouterr().out
    assert "probe points outside the mesh (left out): footing" in printed
    report = json.loads((out / "mesh_report.json").read_text())
    assert report["parts"] == ["subgrade"]
    assert report["node_sets_derived"] == ["bottom", "x_faces", "y_faces"]
    n_probes = len(build_layout(load_case(BASELINE)).probes)      # every probe of the layout
    assert report["probes"] == {} and len(report["probes_outside"]) == n_probes
    with h5py.File(out / "modes.h5", "r") as f:
        freq = f["modes/frequency_hz"][()]
        assert f["mesh/rail_nodes"].size == 0 and f["pads/nodes"].shape == (0, 2)
    assert freq[0] == pytest.approx(14.939, abs=5e-3)
    # the same pencil as the serial assembly, for the round-off tolerance
    from railvib_hpc.mesh.stage import make_mesh
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    case = load_case(BASELINE, [f"mesh.file='{column_msh}'"])
    mesh, _ = make_mesh(case)
    K, M, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, 1), MPI.COMM_SELF)
    assert K.getSize()[0] == 4 * NZ                      # u_z of the 4 x 32 upper nodes
    rtol = frequency_rtol(to_scipy(K), to_scipy(M), freq, solver_tol=case["modal.tol"])
    for n, f in enumerate(freq, start=1):
        assert f == pytest.approx(bar_fixed_free_discrete(n, H, C_P, NZ), rel=rtol[n - 1])
        qh = (2 * n - 1) * np.pi / (2 * H) * (H / NZ)
        assert 0 < f / bar_fixed_free_frequency(n, H, C_P) - 1 <= qh**2 / 24 * 1.05


@pytest.mark.mpi
def test_soil_column_on_all_rank_counts(column_msh, shared_tmp):
    out = shared_tmp / f"column_{comm.size}"
    assert run(_args(column_msh, out)) == 0
    comm.Barrier()
    with h5py.File(out / "modes.h5", "r") as f:
        freq = f["modes/frequency_hz"][()]
    exact = [bar_fixed_free_discrete(n, H, C_P, NZ) for n in (1, 2, 3, 4)]
    # round-off: sqrt(n) u lambda_max / lambda, lambda_max from the assembled pencil
    from fem_tools import frequency_rtol

    from railvib_hpc.mesh.stage import make_mesh
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    case = load_case(BASELINE, [f"mesh.file='{column_msh}'"])
    mesh, _ = make_mesh(case)
    K, M, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, 1), MPI.COMM_SELF)
    rtol = frequency_rtol(to_scipy(K), to_scipy(M), exact, solver_tol=case["modal.tol"])
    assert np.all(np.abs(freq / exact - 1) <= rtol)


def test_stages_that_need_rails_say_so_in_one_line(column_msh, shared_tmp, capsys):
    out = shared_tmp / "column_run"
    code = run(["run", str(BASELINE), "--set", f"mesh.file='{column_msh}'", "--set",
                "modal.n_modes=4", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err
    assert ("the multibody stage needs the flexible rails (part 'rail'), sleepers and rail "
            "pads, which the mesh of") in err and "(it has: subgrade)" in err
    assert (out / "modes.h5").exists() and not (out / "mbs.h5").exists()
    code = run(_args(column_msh, shared_tmp / "column_static", "--set",
                     "mbs.static_correction=true"))
    err = capsys.readouterr().err
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "mbs.static_correction = true (unit loads on the rails) needs the part(s) rail" in err


@pytest.mark.slow
def test_track_without_building_runs_the_whole_pipeline(shared_tmp, capsys):
    """The thesis track and soil (coarse) without the building, as a user .msh: modal, mbs,
    reconstruct and assess complete; the building probes are left out."""
    from railvib_hpc.mesh.gmsh_model import generate
    from railvib_hpc.schema import BUILDING_PARTS, PART_ID

    coarse = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=12", "--set",
              "output.dt=0.01"]
    msh = shared_tmp / "track.msh"
    mesh, _ = generate(build_layout(load_case(BASELINE, ["mesh.refinement=0.5"])))
    keep = ~np.isin(mesh.hex_part, [PART_ID[p] for p in BUILDING_PARTS])
    mesh.hexes, mesh.hex_part = mesh.hexes[keep], mesh.hex_part[keep]
    write_msh(mesh, msh)                      # the building's nodes stay, unused: no DOFs
    out = shared_tmp / "track"
    assert run(["run", str(BASELINE), *coarse, "--set", f"mesh.file='{msh}'", "--out",
                str(out)]) == 0
    printed = capsys.readouterr().out
    slabs = [f"slab{k}{s}" for k in (1, 2) for s in ("", "_x1y1_mid", "_x1y1_corner")]
    assert ("probe points outside the mesh (left out): footing, " + ", ".join(slabs)) in printed
    probes = set(json.loads((out / "assessment.json").read_text())["results"])
    assert "ground_far" in probes and not probes & {"footing", *slabs}
