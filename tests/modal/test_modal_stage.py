"""The modal stage on the thesis model: modes.h5 contents, XDMF, reuse, atomic writes."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.cli import run
from railvib_hpc.config import load_case
from railvib_hpc.io.xdmf import read_xdmf
from railvib_hpc.schema import PART_ID

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
ARGS = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=12"]


@pytest.fixture(scope="module")
def modal_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("modal")
    assert run(["modal", str(BASELINE), *ARGS, "--out", str(out)]) == 0
    return out


def test_modes_file_contents(modal_run):
    case = load_case(BASELINE, ["mesh.refinement=0.5"])
    with h5py.File(modal_run / "modes.h5", "r") as f:
        freq = f["modes/frequency_hz"][()]
        assert len(freq) == 12 and np.all(np.diff(freq) >= 0) and freq[0] > 1.0
        assert np.allclose(f["modes/eigenvalue"][()], (2 * np.pi * freq) ** 2)
        n = f["mesh/points"].shape[0]
        assert f["modes/translation"].shape == (12, n, 3)
        rot_nodes = f["mesh/rotation_nodes"][()]
        assert f["modes/rotation"].shape == (12, len(rot_nodes), 3)
        dofs = f["dofs/index"][()]
        # constrained components are exactly zero: bottom nodes, rigid rails
        bottom = f["mesh/node_sets/bottom"][()]
        assert np.all(f["modes/translation"][:, bottom, :] == 0.0)
        assert np.all(dofs[bottom] == -1)
        # rail nodes: two rails, sorted along x, all flexible-rail nodes
        rails = f["mesh/rail_nodes"][()]
        pts = f["mesh/points"][()]
        assert rails.shape == (2, 36 * round(5 * 0.5) + 1)   # rail elements per bay x 0.5
        assert np.all(np.diff(pts[rails[0], 0]) > 0)
        assert np.allclose(pts[rails, 2], case["geometry.z4"])
        # nodal masses add up to the mass of the model (solids + beams; rigid rails excluded)
        mass = f["mesh/nodal_mass"][()].sum()
        hexes, part = f["mesh/hexes"][()], f["mesh/hex_part"][()]
        assert int(f.attrs["complete"]) == 1 and len(f.attrs["inputs_sha256"]) == 64
        # rail pads kept for the dynamic stage: 3 directions x 2 rails x 37 sleepers
        assert f["pads/nodes"].shape == (3 * 74, 2)
        assert np.bincount(f["pads/direction"][()]).tolist() == [74, 74, 74]
        assert np.all(f["pads/damping"][()] == case["pads.cz"])
    from railvib_hpc.mesh.mesh_io import read_mesh_h5

    mesh, _ = read_mesh_h5(modal_run / "mesh.h5")
    vol = mesh.hex_volumes()
    material = {"ballast": "ballast", "subballast": "subballast", "subgrade": "subgrade",
                **{b: "concrete" for b in ("footing", "column", "beam", "slab", "wall")}}
    rho = {p: case[f"materials.{m}.rho"] for p, m in material.items()}
    expected = sum(rho[p] * vol[part == PART_ID[p]].sum() for p in rho)
    for p, sec in (("rail", "rail"), ("sleeper", "sleeper")):
        conn = mesh.lines[mesh.line_part == PART_ID[p]]
        length = np.linalg.norm(np.diff(mesh.points[conn], axis=1)[:, 0], axis=1).sum()
        expected += case[f"materials.{p}.rho"] * case[f"sections.{sec}.area"] * length
    assert mass == pytest.approx(expected, rel=1e-12)
    assert hexes.shape[1] == 8


def test_modes_xdmf_matches_h5(modal_run):
    """Step k of modes.xdmf shows mode k: row k of /modes/translation, through the views."""
    grids = read_xdmf(modal_run / "modes.xdmf")
    assert len(grids) == 12
    with h5py.File(modal_run / "modes.h5", "r") as f:
        freq = f["modes/frequency_hz"][()]
        for k, g in enumerate(grids):
            assert g["time"] == k + 1 and g["name"] == f"mode_{k + 1}_{freq[k]:.4f}Hz"
            assert np.array_equal(g["points"], f["mesh/points"][()])
            assert np.array_equal(g["cells"], f["mesh/hexes"][()])
            center, shape = g["attributes"]["mode_shape"]
            assert center == "Node" and np.array_equal(shape, f["modes/translation"][k])
            assert np.array_equal(g["attributes"]["part_id"][1], f["mesh/hex_part"][()])


def test_reuse_rewrites_modes_xdmf_of_the_earlier_form(modal_run, capsys):
    """A modes.xdmf without its views (the HyperSlab form, which ParaView's XDMF 3 reader
    shows without data) is rewritten when modes.h5 is reused."""
    (modal_run / "modes_views.h5").unlink()
    stamp = (modal_run / "modes.h5").stat().st_mtime_ns
    capsys.readouterr()
    assert run(["modal", str(BASELINE), *ARGS, "--out", str(modal_run)]) == 0
    text = capsys.readouterr().out
    assert "reusing" in text and f"rewrote {modal_run / 'modes.xdmf'}" in text
    assert (modal_run / "modes.h5").stat().st_mtime_ns == stamp
    assert len(read_xdmf(modal_run / "modes.xdmf")) == 12


@pytest.mark.slow
def test_rerun_reuses_and_physics_change_recomputes(modal_run, capsys):
    stamp = (modal_run / "modes.h5").stat().st_mtime_ns
    capsys.readouterr()
    assert run(["modal", str(BASELINE), *ARGS, "--set", "modal.damping_ratio=0.05",
                "--out", str(modal_run)]) == 0
    assert "reusing" in capsys.readouterr().out
    assert (modal_run / "modes.h5").stat().st_mtime_ns == stamp
    assert run(["modal", str(BASELINE), *ARGS, "--set", "materials.subgrade.E=3e8",
                "--out", str(modal_run)]) == 0
    assert (modal_run / "modes.h5").stat().st_mtime_ns != stamp
    with h5py.File(modal_run / "modes.h5", "r") as f:
        assert "materials.subgrade" in f.attrs["case_toml"] or "[materials.subgrade]" in \
            f.attrs["case_toml"]


@pytest.mark.slow
def test_incomplete_file_is_recomputed_and_failed_write_leaves_nothing(tmp_path, monkeypatch):
    from railvib_hpc.io.formats import modes as modes_io

    out = tmp_path / "res"
    out.mkdir()
    with h5py.File(out / "modes.h5", "w") as f:      # looks like an interrupted run
        f.attrs["complete"] = 0
    assert modes_io.read_modes_summary(out / "modes.h5") is None

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(modes_io, "_write", broken)
    (out / "modes.h5").unlink()
    with pytest.raises(OSError, match="disk full"):
        from railvib_hpc.log import Reporter
        from railvib_hpc.modal.stage import run_modal_stage

        run_modal_stage(load_case(BASELINE, ["mesh.refinement=0.5", "modal.n_modes=4"]), out,
                        MPI.COMM_SELF, Reporter(1))
    assert not (out / "modes.h5").exists()
    assert not [p for p in out.iterdir() if "part" in p.name]


def test_eigensolver_failure_is_reported(tmp_path, capsys):
    code = run(["modal", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
                "modal.n_modes=40", "--set", "modal.max_restarts=1", "--set",
                "modal.max_basis=140", "--out", str(tmp_path)])
    assert code == 2
    err = capsys.readouterr().err
    assert "converged" in err and "modes" in err
    assert not (tmp_path / "modes.h5").exists()


@pytest.mark.slow
def test_strain_energies_in_modes_file_and_material_damping(modal_run, tmp_path, capsys):
    """modes.h5 holds the strain energy of every mode per material, summing to omega^2;
    the MBS turns them into damping ratios; an older modes.h5 without them is recomputed
    by the modal stage and refused by the MBS with a clear message."""
    from modal_cases import energy_sum_allowance, modes_from_file

    from railvib_hpc.io.formats.modes import read_strain_energies
    from railvib_hpc.mbs.case_vehicle import MBSInputError
    from railvib_hpc.mbs.damping_model import modal_damping
    from railvib_hpc.mesh.mesh_io import read_mesh_h5
    from railvib_hpc.model.dofmap import build_dofmap

    energies = read_strain_energies(modal_run / "modes.h5")
    assert set(energies) == {"ballast", "subballast", "subgrade", "concrete", "rail",
                             "sleeper", "pads"}
    # sum = omega^2 and no negative energy, to the round-off of the products
    mesh, _ = read_mesh_h5(modal_run / "mesh.h5")
    dofmap = build_dofmap(mesh, 1)
    lam, phi, _ = modes_from_file(modal_run / "modes.h5", dofmap)
    per_group, total = energy_sum_allowance(mesh, load_case(BASELINE, ARGS[1::2]), dofmap, phi)
    assert np.all(np.abs(sum(energies.values()) - lam) <= total)
    assert all(np.all(e >= -per_group[:, j]) for j, e in enumerate(energies.values()))
    soft = ["materials.subgrade.damping_ratio=0.05", "materials.concrete.damping_ratio=0.01",
            "modal.damping=strain_energy"]
    case = load_case(BASELINE, [*(a for a in ARGS[1::2]), *soft])
    zeta = modal_damping(case, 12, modal_run / "modes.h5")
    share = energies["subgrade"] / lam
    assert np.all((zeta > 0.0) & (zeta < 0.05))
    assert np.argmax(zeta) == np.argmax(share)          # the most soil-dominated mode
    # a modes.h5 without energies (older version): the MBS refuses, the modal stage redoes it
    old = tmp_path / "old"
    assert run(["modal", str(BASELINE), *ARGS, "--out", str(old)]) == 0
    with h5py.File(old / "modes.h5", "a") as f:
        del f["modes/strain_energy"]
    # as if written that way (an edit after writing is otherwise detected as corruption)
    from railvib_hpc.io.digests import record_file

    record_file(old / "modes.h5")
    # with uniform damping such a file is simply reused
    assert run(["modal", str(BASELINE), *ARGS, "--out", str(old)]) == 0
    assert "reusing" in capsys.readouterr().out
    with pytest.raises(MBSInputError, match="holds no per-material strain energies"):
        modal_damping(case, 12, old / "modes.h5")
    args = [*ARGS, *(x for s_ in soft for x in ("--set", s_))]
    assert run(["modal", str(BASELINE), *args, "--out", str(old)]) == 0
    assert "has no per-material strain energies" in capsys.readouterr().out
    assert read_strain_energies(old / "modes.h5") is not None
