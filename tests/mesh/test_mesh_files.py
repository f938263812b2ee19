"""mesh.h5 / mesh.xdmf: readable by ParaView's XDMF reader, atomic, reused on rerun."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.mesh.mesh_io import read_mesh_h5

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"


def test_mesh_command_writes_consistent_xdmf_and_h5(tmp_path):
    out = tmp_path / "res"
    assert run(["mesh", str(BASELINE), "--set", "mesh.refinement=0.5", "--out", str(out)]) == 0
    assert {p.name for p in out.iterdir()} == {".railvib", "mesh.h5", "mesh.xdmf", "mesh.msh",
                                               "mesh_report.json", "run.json"}
    root = ET.parse(out / "mesh.xdmf").getroot()
    with h5py.File(out / "mesh.h5", "r") as f:
        for item in root.iter("DataItem"):
            fname, dset = item.text.strip().split(":")
            assert fname == "mesh.h5"
            dims = tuple(int(d) for d in item.attrib["Dimensions"].split())
            assert f[dset].shape == dims, dset
        grids = {g.attrib["Name"]: g for g in root.iter("Grid")}
        assert grids["solids"].find("Topology").attrib["TopologyType"] == "Hexahedron"
        assert int(grids["solids"].find("Topology").attrib["NumberOfElements"]) == \
            f["mesh/hexes"].shape[0]
        assert f["mesh/hexes"][()].max() < f["mesh/points"].shape[0]
        assert "inputs_sha256" in f.attrs and "case_toml" in f.attrs
    mesh, _ = read_mesh_h5(out / "mesh.h5")
    assert np.all(mesh.hex_volumes() > 0)


@pytest.mark.slow
def test_rerun_reuses_and_changed_input_rebuilds(tmp_path, capsys):
    out = tmp_path / "res"
    args = ["mesh", str(BASELINE), "--set", "mesh.refinement=0.5", "--out", str(out)]
    assert run(args) == 0
    stamp = (out / "mesh.h5").stat().st_mtime_ns
    capsys.readouterr()
    assert run(args) == 0
    assert "reusing" in capsys.readouterr().out
    assert (out / "mesh.h5").stat().st_mtime_ns == stamp
    # materials do not change the mesh; geometry does
    assert run(args + ["--set", "materials.rail.E=2e11"]) == 0
    assert (out / "mesh.h5").stat().st_mtime_ns == stamp
    assert run(args + ["--set", "domain.extra_depth=1.0"]) == 0
    assert (out / "mesh.h5").stat().st_mtime_ns != stamp
    assert not list(out.glob(".*part*"))


@pytest.mark.slow
def test_corrupt_previous_result_is_rebuilt(tmp_path):
    out = tmp_path / "res"
    args = ["mesh", str(BASELINE), "--set", "mesh.refinement=0.5", "--out", str(out)]
    assert run(args) == 0
    (out / "mesh.h5").write_bytes(b"not hdf5")
    assert run(args) == 0
    mesh, _ = read_mesh_h5(out / "mesh.h5")
    assert mesh.n_nodes > 0
