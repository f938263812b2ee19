"""Layered soil ([[soil.layers]]) and the soil measures ([trench], [wib]).

The layers: the exact two-layer column, the layout, the checks.

The physics check is the 1D site-response column of two layers on a rigid base: a top
layer (thickness h1, c1, rho1) over a bottom layer (h2, c2, rho2). With the free
surface and the fixed base, continuity of displacement and shear stress at the interface
gives the transfer-matrix frequency equation

    Z1 sin(w h1 / c1) sin(w h2 / c2) = Z2 cos(w h1 / c1) cos(w h2 / c2),   Z = rho c,

i.e. ``tan(a) tan(b) = Z2 / Z1`` (for Z1 = Z2 it reduces to cos(a + b) = 0, the
homogeneous column's (2m - 1) c / 4H). The column is meshed with hexahedra whose part
ids are the layers', and its matrices come from the model's own element batches, so the
layer materials travel the path the solver uses (``soil_layers`` -> ``solid_material`` ->
``element_batches``).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from fem_tools import box_mesh
from scipy.optimize import brentq

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError
from railvib_hpc.fem import lowest_modes
from railvib_hpc.fem.assemble_serial import assemble_matrix
from railvib_hpc.mesh.layout import build_layout
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.mesh.stage import predicted_hexes, wavelength_warnings
from railvib_hpc.model.elements import element_batches
from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID
from railvib_hpc.site import soil_layers

H1, C1, RHO1, NU1 = 2.0, 120.0, 1750.0, 0.30     # soft top layer
H2, C2, RHO2, NU2 = 4.0, 300.0, 2000.0, 0.25     # stiffer layer down to the base
LAYERS = [{"thickness": H1, "c_s": C1, "nu": NU1, "rho": RHO1},
          {"thickness": 0.0, "c_s": C2, "nu": NU2, "rho": RHO2}]


def exact_two_layer(n: int) -> np.ndarray:
    """The lowest ``n`` shear frequencies (Hz) of the two-layer column on a rigid base."""
    z1, z2 = RHO1 * C1, RHO2 * C2

    def g(w: float) -> float:
        a, b = w * H1 / C1, w * H2 / C2
        return z1 * np.sin(a) * np.sin(b) - z2 * np.cos(a) * np.cos(b)

    grid = np.linspace(1e-6, 2 * np.pi * 200.0, 200_001)
    vals = g(grid)
    roots = [brentq(g, grid[k], grid[k + 1], xtol=1e-14, rtol=1e-15)
             for k in np.flatnonzero(np.sign(vals[:-1]) != np.sign(vals[1:]))[:n]]
    return np.array(roots) / (2 * np.pi)


def column_case() -> Case:
    """A case whose soil is :data:`LAYERS` over a base H1 + H2 below the ground."""
    z1 = Case.defaults()["geometry.z1"]
    return Case.defaults().replace({"geometry.z0": z1 - (H1 + H2), "soil.layers": LAYERS})


def layered_column_frequencies(n_top: int, n_modes: int) -> np.ndarray:
    """x-shear frequencies of a 1 x 1 x (3 n_top) hex column, layers by part id.

    The four nodes of a level move together (periodic lateral ties) and only u_x is kept:
    x-shear decouples exactly from the other motions of an isotropic column.
    """
    n_bottom = 2 * n_top                       # equal element heights (H2 = 2 H1)
    n = n_top + n_bottom
    pts, hexes = box_mesh(1, 1, n, 1.0, 1.0, H1 + H2)
    zc = pts[hexes][:, :, 2].mean(axis=1)
    part = np.where(zc > H2, PART_ID["soil_layer_1"], PART_ID["soil_layer_2"]).astype(np.int32)
    mesh = Mesh(points=pts, hexes=hexes, hex_part=part, lines=np.zeros((0, 2), np.int64),
                line_part=np.zeros(0, np.int32))
    index = np.arange(3 * len(pts)).reshape(-1, 3)
    ndof = 3 * len(pts)
    K = sp.csr_matrix((ndof, ndof))
    M = sp.csr_matrix((ndof, ndof))
    for batch in element_batches(mesh, Problem.from_case(column_case())):
        dofs = batch.dofs(index)
        K = K + assemble_matrix(dofs, batch.K, ndof)
        M = M + assemble_matrix(dofs, batch.M, ndof)
    level = np.rint(pts[:, 2] / ((H1 + H2) / n)).astype(int)
    keep = level >= 1
    rows = 3 * np.flatnonzero(keep)                       # u_x of the nodes above the base
    P = sp.csr_matrix((np.ones(len(rows)), (rows, level[keep] - 1)), shape=(ndof, n))
    Kr, Mr = (P.T @ K @ P).tocsc(), (P.T @ M @ P).tocsc()
    return lowest_modes(Kr, Mr, n_modes, sigma=0.0, dense_below=0)[0]


def test_layer_properties_from_c_s():
    layers = soil_layers(column_case())
    assert [x["part"] for x in layers] == ["soil_layer_1", "soil_layer_2"]
    assert layers[0]["E"] == pytest.approx(2 * RHO1 * C1**2 * (1 + NU1), rel=1e-15)
    z1 = layers[0]["z_top"]
    assert layers[0]["z_bottom"] == pytest.approx(z1 - H1, abs=1e-12)
    assert layers[1]["z_bottom"] == pytest.approx(z1 - H1 - H2, abs=1e-12)   # 0: to the base


def test_two_layer_column_converges_to_the_transfer_matrix_solution():
    exact = exact_two_layer(3)
    homogeneous = (2 * np.arange(1, 4) - 1) * C1 / (4 * (H1 + H2))
    assert np.all(np.abs(exact / homogeneous - 1) > 0.2)     # the layering matters here
    ns = np.array([4, 8, 16, 32])
    err = np.array([layered_column_frequencies(n, 3) / exact - 1 for n in ns])
    assert np.all(err > 0)                     # consistent mass: from above
    h = (H1 + H2) / (3 * ns)
    for j in range(3):
        slope = np.polyfit(np.log(h), np.log(err[:, j]), 1)[0]
        assert 1.9 < slope < 2.15, (j, slope, err[:, j])
    # (k h)^2 / 24 in the softer layer bounds the finest error
    k1 = 2 * np.pi * exact / C1
    assert np.all(err[-1] < (k1 * h[-1]) ** 2 / 24 * 1.5)


def thesis_case() -> Case:
    from pathlib import Path

    return Case.from_file(Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml")


def test_layout_places_the_layers_and_keeps_the_thesis_mesh():
    case = thesis_case()
    assert predicted_hexes(build_layout(case)) == 41_880       # no layers: the thesis mesh
    layered = case.replace({"soil.layers": [
        {"thickness": 1.5, "c_s": 120.0, "nu": 0.3, "rho": 1750.0},
        {"thickness": 0.0, "E": 4e8, "nu": 0.25, "rho": 2000.0}]})
    lay = build_layout(layered)
    parts = {b.part for b in lay.blocks}
    assert {"soil_layer_1", "soil_layer_2"} <= parts and "subgrade" not in parts
    z1 = case["geometry.z1"]
    for b in lay.blocks:
        if b.part == "soil_layer_1":
            assert b.z0 >= z1 - 1.5 - 1e-9 and b.z1 <= z1 + 1e-9
        if b.part == "soil_layer_2":
            assert b.z1 <= z1 - 1.5 + 1e-9
    # the same soil volume as the homogeneous subgrade (only the materials differ)
    def soil_volume(lay) -> float:
        total = 0.0
        for b in lay.blocks:
            if b.part in ("subgrade", "soil_layer_1", "soil_layer_2"):
                total += (lay.xb[b.i + 1] - lay.xb[b.i]) * (lay.yb[b.j + 1] - lay.yb[b.j]) \
                    * (b.z1 - b.z0)
        return total
    assert soil_volume(lay) == pytest.approx(soil_volume(build_layout(case)), rel=1e-12)


def test_wavelength_sizing_resolves_every_layer():
    case = thesis_case().replace({
        "soil.layers": LAYERS[:1] + [{"thickness": 0.0, "c_s": C2, "nu": NU2, "rho": RHO2}],
        "mesh.elements_per_wavelength": 6.0, "mesh.wavelength_hz": 30.0})
    lay = build_layout(case)
    for b in lay.blocks:
        c = {"soil_layer_1": C1, "soil_layer_2": C2}.get(b.part)
        if c is None:
            continue
        n = lay.zdiv[(round(b.z0, 9), round(b.z1, 9))]
        assert (b.z1 - b.z0) / n <= c / 30.0 / 6.0 + 1e-9
        # horizontally: the softest soil's size everywhere
        assert (lay.xb[b.i + 1] - lay.xb[b.i]) / lay.nx[b.i] <= C1 / 30.0 / 6.0 + 1e-9


def test_under_resolved_band_warns_once_per_part():
    case = column_case().replace({"modal.f_max": 40.0})
    quality = {"max_edge_per_soil_part": {"soil_layer_1": 1.0, "soil_layer_2": 1.0}}
    warnings = wavelength_warnings(quality, case)
    # soil_layer_1: 120 / 40 = 3 m wavelength, 3 elements < 6; soil_layer_2: 7.5 m, 7.5 >= 6
    assert len(warnings) == 1
    assert warnings[0].startswith("modal.f_max = 40 Hz is under-resolved in soil_layer_1")
    assert "3 per wavelength < mesh.min_elements_per_wavelength = 6" in warnings[0]
    assert wavelength_warnings(quality, column_case()) == []         # no band: no check


@pytest.mark.parametrize("layers, key, words", [
    ([{"thickness": 2.0, "c_s": 100.0, "nu": 0.3, "rho": 1800.0}], "soil.layers",
     "do not reach the base: it lies 4.8 m below the ground"),
    ([{"thickness": 5.0, "c_s": 100.0, "nu": 0.3, "rho": 1800.0},
      {"thickness": 0.0, "c_s": 200.0, "nu": 0.3, "rho": 1800.0}], "soil.layers[2]",
     "lies below the base"),
    ([{"thickness": 5.0, "c_s": 100.0, "E": 1e8, "nu": 0.3, "rho": 1800.0}],
     "soil.layers[1].E", "give exactly one of E (Pa) and c_s (m/s)"),
    ([{"thickness": 5.0, "c_s": 100.0, "rho": 1800.0}], "soil.layers[1].nu", "missing"),
    ([{"thickness": 5.0, "c_s": 100.0, "nu": 0.5, "rho": 1800.0}], "soil.layers[1].nu",
     "0 <= nu < 0.5"),
    ([{"thickness": 0.0, "c_s": 100.0, "nu": 0.3, "rho": 1800.0},
      {"thickness": 0.0, "c_s": 100.0, "nu": 0.3, "rho": 1800.0}], "soil.layers[1].thickness",
     "the last layer may give 0"),
    ([{"thickness": 5.0, "c_s": 100.0, "nu": 0.3, "rho": 1800.0, "depth": 2}],
     "soil.layers[1].depth", "unknown key; allowed: thickness, E, c_s"),
    ({"thickness": 5.0}, "soil.layers.thickness", "write [[soil.layers]] (double brackets)"),
    ("soft", "soil.layers", "expected a list of tables"),
])
def test_bad_layers_get_one_clear_line(layers, key, words):
    with pytest.raises(CaseError) as info:
        Case.defaults().replace({"soil.layers": layers})
    lines = str(info.value).splitlines()
    hits = [ln for ln in lines if ln.strip().startswith(f"{key} =") or f": {key} =" in ln]
    assert hits and words in hits[0], lines


def test_wavelength_sizing_needs_its_frequency():
    with pytest.raises(CaseError) as info:
        Case.defaults().replace({"mesh.elements_per_wavelength": 6.0})
    assert "mesh.elements_per_wavelength = 6.0: needs mesh.wavelength_hz > 0" in str(info.value)


# --- the soil measures: trench and wave-impeding block -------------------------------------

TRENCH = {"trench.distance": 6.0, "trench.width": 0.6, "trench.depth": 3.0}
WIB = {"wib.width": 6.0, "wib.depth": 1.0, "wib.thickness": 1.0}


def _parts(lay) -> dict[str, float]:
    """Volume of every part of a layout's blocks."""
    out: dict[str, float] = {}
    for b in lay.blocks:
        vol = (lay.xb[b.i + 1] - lay.xb[b.i]) * (lay.yb[b.j + 1] - lay.yb[b.j]) * (b.z1 - b.z0)
        out[b.part] = out.get(b.part, 0.0) + vol
    return out


def test_trench_and_block_take_their_volume_from_the_soil():
    case = thesis_case()
    length = case["geometry.x4"] - case["geometry.x1"]
    none = _parts(build_layout(case.replace({"trench.type": "none", **TRENCH})))
    open_ = _parts(build_layout(case.replace({"trench.type": "open", **TRENCH})))
    filled = _parts(build_layout(case.replace({"trench.type": "filled", **TRENCH})))
    trench = length * 0.6 * 3.0
    assert "trench_fill" not in none and "trench_fill" not in open_
    assert none["subgrade"] - open_["subgrade"] == pytest.approx(trench, rel=1e-12)
    assert filled["trench_fill"] == pytest.approx(trench, rel=1e-12)
    assert filled["subgrade"] == pytest.approx(open_["subgrade"], rel=1e-12)
    wib = _parts(build_layout(case.replace({"wib.type": "block", **WIB})))
    assert wib["wib"] == pytest.approx(length * 6.0 * 1.0, rel=1e-12)
    # type 'none' keeps only the lines; without a width there are none, and the trench's
    # other sizes do not apply (refused, not ignored)
    with pytest.raises(CaseError, match=r"trench\.depth = 3\.0: applies to trench\.type != "
                                        r"'none' or trench\.width > 0 only"):
        case.replace({"trench.depth": 3.0})


def test_a_probe_in_the_trench_moves_in_front_of_it_on_both_meshes():
    case = thesis_case().replace({"trench.distance": 6.5, "trench.width": 1.2,
                                  "trench.depth": 3.0})
    for kind in ("none", "open"):
        y = build_layout(case.replace({"trench.type": kind})).probes["ground_mid"][1]
        assert y == pytest.approx(-0.5 * (-case["geometry.ys1"] + 6.5))


@pytest.mark.parametrize("changes, key, words", [
    ({"trench.type": "open", **TRENCH, "trench.distance": 2.0}, "trench.distance",
     "beyond the embankment toe"),
    ({"trench.type": "open", **TRENCH, "trench.width": 5.0}, "trench.width",
     "would cut through the building"),
    ({"trench.type": "filled", **TRENCH, "trench.depth": 4.8}, "trench.depth",
     "less than the soil depth"),
    ({"trench.type": "open"}, "trench.width", "must be > 0 m for trench.type = 'open'"),
    ({"wib.type": "block", **WIB, "wib.width": 9.0}, "wib.width", "embankment base"),
    ({"wib.type": "block", **WIB, "wib.depth": 4.0}, "wib.thickness", "must end above the base"),
])
def test_bad_measures_get_one_clear_line(changes, key, words):
    with pytest.raises(CaseError) as info:
        thesis_case().replace(changes)
    hits = [ln for ln in str(info.value).splitlines() if f"{key} = " in ln]
    assert hits and words in hits[0], str(info.value)


@pytest.mark.parametrize("user_mesh", [False, True])
def test_stresses_find_the_layer_materials_in_modes_h5(tmp_path, user_mesh):
    """The reconstruct stage rebuilds the materials from the case stored in modes.h5."""
    import h5py

    from railvib_hpc.reconstruct.stress import hex_materials

    case = column_case()
    text = case.to_toml()
    if user_mesh:           # a user's .msh with layer parts: its levels are not checked
        text = text.replace('file = ""', 'file = "site.msh"', 1)
        assert 'file = "site.msh"' in text
    with h5py.File(tmp_path / "modes.h5", "w") as f:
        f.attrs["case_toml"] = text
        mats = hex_materials(Problem.from_modes(f))
    for k, (c, rho, nu) in enumerate(((C1, RHO1, NU1), (C2, RHO2, NU2)), start=1):
        assert mats[PART_ID[f"soil_layer_{k}"]] == pytest.approx((2 * rho * c**2 * (1 + nu), nu),
                                                                rel=1e-12)
