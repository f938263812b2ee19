"""The rails' modal rows read from a real modes.h5 (coarse thesis model)."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.mbs import read_rail_modes

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"


@pytest.fixture(scope="module")
def modes_file(tmp_path_factory):
    out = tmp_path_factory.mktemp("mbs_modes")
    assert run(["modal", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
                "modal.n_modes=10", "--out", str(out)]) == 0
    return out / "modes.h5"


def test_rail_rows_match_the_file(modes_file):
    rm = read_rail_modes(modes_file)
    with h5py.File(modes_file, "r") as f:
        freq = f["modes/frequency_hz"][()]
        nodes = f["mesh/rail_nodes"][()]
        trans = f["modes/translation"][()]
        pts = f["mesh/points"][()]
    assert rm.omega == pytest.approx(2 * np.pi * freq, rel=1e-12)
    assert rm.rail_z == pytest.approx(6.00424)
    assert np.allclose(np.sort(np.abs(rm.rail_y)), 0.75565)
    for rail, n in zip(rm.rails, nodes):
        assert np.array_equal(rail.x_nodes, pts[n, 0])
        assert np.allclose(rail.phi_w, trans[:, n, 2])
        # the joints with the rigid rails are fixed: zero displacement and rotation there
        assert np.allclose(rail.phi_w[:, [0, -1]], 0.0) and np.allclose(rail.phi_r[:, [0, -1]], 0)
        # interpolation at a node returns the nodal modal values (Hermite, same shape functions
        # as the force distribution)
        k = len(n) // 2
        q = np.random.default_rng(0).standard_normal(len(freq))
        assert rail.displacement(np.array([rail.x_nodes[k]]), q)[0] == \
            pytest.approx(rail.phi_w[:, k] @ q, rel=1e-12, abs=1e-18)
    assert len(read_rail_modes(modes_file, n_modes=4).omega) == 4


def test_incomplete_file_is_refused(tmp_path):
    bad = tmp_path / "modes.h5"
    with h5py.File(bad, "w") as f:
        f.attrs["complete"] = 0
    with pytest.raises(ValueError, match="not a complete modes file"):
        read_rail_modes(bad)
