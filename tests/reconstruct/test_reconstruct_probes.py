"""Probe histories from the modal basis: exact for linear fields, nodal values, writers."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from reconstruct_cases import (
    box_mesh,
    histories,
    read_modes,
    relative_error,
    write_static_basis,
    write_synthetic_modes,
)

from railvib_hpc.errors import UserError
from railvib_hpc.fem.reference import hex_shape_values
from railvib_hpc.reconstruct import (
    ProbeError,
    mesh_probes,
    probe_histories,
    probe_modes,
    reconstruct_fields,
    write_probes_csv,
    write_probes_h5,
)
from railvib_hpc.reconstruct.probes import CSV_HEADER


@pytest.fixture(scope="module")
def linear_modes(tmp_path_factory):
    """A distorted block whose 3 'modes' are linear fields u_k = a_k + B_k x."""
    mesh = box_mesh(3, 2, 2, distort=0.2)
    rng = np.random.default_rng(7)
    a = rng.standard_normal((3, 3))
    B = rng.standard_normal((3, 3, 3))
    translation = a[:, None, :] + np.einsum("kij,nj->kni", B, mesh.points)
    path = tmp_path_factory.mktemp("linear") / "modes.h5"
    write_synthetic_modes(path, mesh, translation)
    return path, mesh, a, B


def test_probe_interpolation_is_exact_for_linear_fields(linear_modes):
    path, mesh, a, B = linear_modes
    rng = np.random.default_rng(8)
    # random points well inside the (distorted) block, plus the stored mesh probe
    pts = rng.uniform([0.3, 0.3, 0.3], [2.7, 1.7, 1.7], size=(25, 3))
    phi, elem, xi = probe_modes(path, pts, 3)
    assert phi.shape == (25, 3, 3) and np.all(elem >= 0) and np.all(np.abs(xi) <= 1)
    exact = a[None] + np.einsum("kij,pj->pki", B, pts)
    assert np.abs(phi - exact).max() < 1e-12 * np.abs(exact).max()
    # the located element really contains the point: x(xi) = p
    x = np.einsum("pa,pai->pi", hex_shape_values(xi), mesh.points[mesh.hexes[elem]])
    assert np.allclose(x, pts, atol=1e-12)


def test_probe_at_a_node_equals_the_nodal_value(coarse_modes):
    m = 8
    phi_all, mesh = read_modes(coarse_modes, m)
    used = np.unique(mesh["hexes"])
    nodes = used[np.linspace(0, len(used) - 1, 40).astype(int)]
    phi, _, _ = probe_modes(coarse_modes, mesh["points"][nodes], m)
    ref = phi_all[:, nodes].transpose(1, 0, 2)
    assert np.abs(phi - ref).max() <= 1e-12 * np.abs(phi_all).max()


def test_histories_equal_interpolated_fields(coarse_modes, tmp_path):
    m = 6
    t, q, qd, qdd = histories(15, m, seed=11)
    with h5py.File(coarse_modes, "r") as f:
        n = f["mesh/points"].shape[0]
    write_static_basis(tmp_path / "static.h5", n, 2)
    rng = np.random.default_rng(2)
    g = [rng.standard_normal((15, 2)) for _ in range(3)]
    extra = [(tmp_path / "static.h5", "basis", *g)]
    user = {"near_building": (14.0, -9.0, 4.0)}
    hist = probe_histories(coarse_modes, t, q, qd, qdd, user_probes=user, extra=extra)
    stored = mesh_probes(coarse_modes)
    assert list(hist) == list(stored) + ["near_building"]
    # reference: interpolate the nodal fields of fields.h5 with the shape functions
    reconstruct_fields(coarse_modes, tmp_path / "fields.h5", MPI.COMM_SELF, t, q, qd, qdd,
                       extra=extra)
    with h5py.File(tmp_path / "fields.h5", "r") as f:
        hexes = f["mesh/hexes"][()]
        fields = {k: f["fields/" + k][()] for k in ("displacement", "velocity",
                                                     "acceleration")}
    for name, h in hist.items():
        nodes = hexes[h["element"]]
        w = hex_shape_values(h["xi"])
        for key, data in fields.items():
            ref = np.einsum("a,tai->ti", w, data[:, nodes])
            assert h[key].shape == (15, 3)
            assert relative_error(h[key], ref) < 1e-12, (name, key)
        assert np.array_equal(h["t"], t)
    assert np.allclose(hist["near_building"]["coords"], user["near_building"])


def test_unnamed_user_probes_and_errors(linear_modes):
    path, _, _, _ = linear_modes
    t, q, qd, qdd = histories(4, 3)
    hist = probe_histories(path, t, q, qd, qdd, user_probes=[(1.0, 1.0, 1.0), (2, 1, 0.5)])
    assert list(hist) == ["centre", "user_1", "user_2"]
    with pytest.raises(ProbeError, match=r"'user_1' at \(10.0, 0.0, 0.0\)"):
        probe_histories(path, t, q, qd, qdd, user_probes=[(10.0, 0.0, 0.0)])
    with pytest.raises(UserError, match="three finite numbers"):
        probe_histories(path, t, q, qd, qdd, user_probes={"bad": (1.0, 2.0)})
    with pytest.raises(ProbeError, match="name of a probe of the mesh"):
        probe_histories(path, t, q, qd, qdd, user_probes={"centre": (1.0, 1.0, 1.0)})


def test_csv_and_h5_writers(linear_modes, tmp_path):
    path, _, _, _ = linear_modes
    t, q, qd, qdd = histories(6, 3)
    hist = probe_histories(path, t, q, qd, qdd, user_probes={"a/b": (1.0, 1.0, 1.0)})
    files = write_probes_csv(tmp_path / "probes", hist)
    assert sorted(p.name for p in files) == ["a_b.csv", "centre.csv"]
    assert sorted(p.name for p in (tmp_path / "probes").iterdir()) == ["a_b.csv", "centre.csv"]
    text = (tmp_path / "probes" / "centre.csv").read_text().splitlines()
    assert text[0] == CSV_HEADER and len(text) == 7
    data = np.loadtxt(tmp_path / "probes" / "centre.csv", delimiter=",", skiprows=1)
    h = hist["centre"]
    assert np.array_equal(data, np.column_stack([t, h["displacement"], h["velocity"],
                                                 h["acceleration"]]))
    write_probes_h5(tmp_path / "probes.h5", hist, attrs={"inputs_sha256": "k"},
                    groups={"rail": {"x": np.arange(3.0)}})
    with h5py.File(tmp_path / "probes.h5", "r") as f:
        assert [n.decode() for n in f["names"][()]] == ["centre", "a/b"]
        assert f["names"].dtype == np.dtype("S64")
        assert int(f.attrs["complete"]) == 1 and f.attrs["inputs_sha256"] == "k"
        g = f["probes/a_b"]
        assert g.attrs["name"] == "a/b" and np.allclose(g.attrs["coords"], 1.0)
        for key in ("displacement", "velocity", "acceleration"):
            assert np.array_equal(g[key][()], hist["a/b"][key])
        assert np.array_equal(f["rail/x"][()], np.arange(3.0))
    assert sorted(p.name for p in tmp_path.iterdir()) == [".railvib", "probes", "probes.h5"]


def test_probe_histories_are_q_times_phi(linear_modes):
    path, _, _, _ = linear_modes
    t, q, qd, qdd = histories(9, 2)
    hist = probe_histories(path, t, q, qd, qdd)
    phi, _, _ = probe_modes(path, [mesh_probes(path)["centre"]], 2)
    for key, h in (("displacement", q), ("velocity", qd), ("acceleration", qdd)):
        assert np.allclose(hist["centre"][key], h @ phi[0], rtol=1e-14, atol=0)


def test_probe_roles_travel_from_the_definition_to_probes_h5_and_the_assessment(linear_modes,
                                                                                tmp_path):
    """Mesh probes keep the role they were defined with; user probes default to 'ground'."""
    from railvib_hpc.assess.stage import read_probes
    from railvib_hpc.assess.standards import DIN4150_3_LOCATION_OF_ROLE

    path, _, _, _ = linear_modes
    t, q, qd, qdd = histories(6, 3)
    hist = probe_histories(path, t, q, qd, qdd,
                           user_probes={"u1": (1.0, 1.0, 1.0), "u2": (2.0, 1.0, 0.5)},
                           user_roles={"u2": "wall"})
    assert {k: h["role"] for k, h in hist.items()} == {"centre": "floor", "u1": "ground",
                                                       "u2": "wall"}
    write_probes_h5(tmp_path / "probes.h5", hist)
    back = read_probes(tmp_path / "probes.h5")
    assert {k: h["role"] for k, h in back.items()} == {"centre": "floor", "u1": "ground",
                                                       "u2": "wall"}
    assert [DIN4150_3_LOCATION_OF_ROLE[h["role"]] for h in back.values()] == [
        "floor", "foundation", "foundation"]
    with pytest.raises(ProbeError, match="role 'roof' is not one of"):
        probe_histories(path, t, q, qd, qdd, user_probes={"u1": (1.0, 1.0, 1.0)},
                        user_roles={"u1": "roof"})


def test_layout_probes_carry_their_roles():
    from railvib_hpc.config import load_case
    from railvib_hpc.mesh.layout import build_layout
    from railvib_hpc.schema import PROBE_ROLES

    layout = build_layout(load_case(None))
    assert set(layout.probe_roles) == set(layout.probes)
    # every role but free_field, which only the points of [[probes.line]] carry
    assert set(layout.probe_roles.values()) == set(PROBE_ROLES) - {"free_field"}
    assert layout.probe_roles["slab1"] == layout.probe_roles["slab2"] == "floor"
    assert layout.probe_roles["footing"] == "foundation"
    assert layout.probe_roles["basement_wall"] == "wall"


def test_modes_without_probe_roles_are_named(linear_modes, tmp_path):
    """A modes.h5 of a version before probe roles: one clear error, not a silent default."""
    import shutil

    path, _, _, _ = linear_modes
    old = tmp_path / "modes.h5"
    shutil.copy(path, old)
    with h5py.File(old, "a") as f:
        del f["mesh/probes/roles"]
    t, q, qd, qdd = histories(4, 3)
    with pytest.raises(ProbeError, match=r"stores no probe roles.*rerun 'railvib modal'"):
        probe_histories(old, t, q, qd, qdd)
    assert list(probe_histories(old, t, q, qd, qdd, mesh=False,
                                user_probes={"u": (1.0, 1.0, 1.0)})) == ["u"]
