"""The XDMF writer: plain HDF DataItems, per-step views in a sidecar, checks on reading."""

from __future__ import annotations

import os
import shutil
import xml.etree.ElementTree as ET

import h5py
import numpy as np
import pytest

from railvib_hpc.io.xdmf import (
    CellBlock,
    H5Array,
    Series,
    ensure_views,
    has_views,
    hex_mesh,
    mesh_document,
    read_xdmf,
    remove_xdmf,
    views_path,
    write_series,
)

NS, N, NE = 4, 12, 2


def _data_file(path):
    rng = np.random.default_rng(1)
    with h5py.File(path, "w") as f:
        f["mesh/points"] = rng.standard_normal((N, 3))
        f["mesh/hexes"] = np.arange(16, dtype=np.int64).reshape(NE, 8) % N
        f["mesh/hex_part"] = np.array([3, 7], dtype=np.int32)
        f["time"] = np.linspace(0.0, 0.3, NS)
        f["fields/u"] = rng.standard_normal((NS, N, 3)).astype(np.float32)
        f["stress/s"] = rng.standard_normal((NS, NE))
        f["stress/flag"] = rng.integers(0, 9, (NS, NE), dtype=np.int16)


def _write(tmp_path):
    data = tmp_path / "data.h5"
    _data_file(data)
    with h5py.File(data, "r") as f:
        points, block = hex_mesh(f)
        series = [Series("u", H5Array.of(f, "fields/u"), "Node"),
                  Series("s", H5Array.of(f, "stress/s"), "Cell"),
                  Series("flag", H5Array.of(f, "stress/flag"), "Cell")]
        times = f["time"][()]
    write_series(tmp_path / "data.xdmf", points, block, times, series)
    return data, times


def test_every_step_is_a_plain_item_of_its_own_view(tmp_path):
    data, times = _write(tmp_path)
    root = ET.parse(tmp_path / "data.xdmf").getroot()
    items = list(root.iter("DataItem"))
    # no HyperSlab/Function references: the XDMF 3 reader cannot type them before reading
    assert all(i.get("Format") == "HDF" and "ItemType" not in i.attrib for i in items)
    assert {i.text.split(":")[0] for i in items} == {"data.h5", "data_views.h5"}
    grids = read_xdmf(tmp_path / "data.xdmf")
    assert [g["time"] for g in grids] == list(times)
    with h5py.File(data, "r") as f:
        for k, g in enumerate(grids):
            assert g["name"] == f"data_{k}"
            assert g["attributes"]["u"][0] == "Node"
            u = g["attributes"]["u"][1]
            assert u.dtype == np.float32 and np.array_equal(u, f["fields/u"][k])
            assert np.array_equal(g["attributes"]["s"][1], f["stress/s"][k])
            assert np.array_equal(g["attributes"]["flag"][1], f["stress/flag"][k])
            assert np.array_equal(g["attributes"]["part_id"][1], [3, 7])
    vector = root.find(".//Attribute[@Name='u']")
    assert vector.get("AttributeType") == "Vector"
    assert root.find(".//Attribute[@Name='s']").get("AttributeType") == "Scalar"


def test_views_follow_the_folder_and_a_missing_source_reads_nan(tmp_path, monkeypatch):
    (tmp_path / "a").mkdir()
    _write(tmp_path / "a")
    moved = tmp_path / "b"
    shutil.move(tmp_path / "a", moved)
    monkeypatch.chdir(tmp_path)                      # neither the data nor the views folder
    grids = read_xdmf(moved / "data.xdmf")
    with h5py.File(moved / "data.h5", "r") as f:
        assert np.array_equal(grids[2]["attributes"]["u"][1], f["fields/u"][2])
    os.unlink(moved / "data.h5")
    with h5py.File(moved / "data_views.h5", "r") as f:
        # never a plausible zero field
        assert np.isnan(f["fields/u/000001"][()]).all()
        assert np.isnan(f["stress/s/000003"][()]).all()


def test_reading_checks_dimensions_and_precision(tmp_path):
    _write(tmp_path)
    xdmf = tmp_path / "data.xdmf"
    text = xdmf.read_text()
    xdmf.write_text(text.replace(f'Dimensions="{N} 3" NumberType="Float" Precision="4"',
                                 f'Dimensions="{N} 3" NumberType="Float" Precision="8"', 1))
    with pytest.raises(ValueError, match="the DataItem says"):
        read_xdmf(xdmf)


def test_mesh_document_shares_points_and_leaves_out_empty_blocks(tmp_path):
    pts = H5Array("m.h5", "/mesh/points", (N, 3), "<f8")
    hexes = H5Array("m.h5", "/mesh/hexes", (NE, 8), "<i8")
    lines = H5Array("m.h5", "/mesh/lines", (0, 2), "<i8")
    root = ET.fromstring(mesh_document(pts, [CellBlock("solids", "Hexahedron", hexes),
                                             CellBlock("beams", "Polyline", lines)]))
    grids = root.findall(".//Grid[@GridType='Uniform']")
    assert [g.get("Name") for g in grids] == ["solids"]
    with pytest.raises(ValueError, match="Hexahedron cells must be"):
        mesh_document(pts, [CellBlock("bad", "Hexahedron",
                                      H5Array("m.h5", "/x", (3, 4), "<i8"))])


def test_steps_must_match_the_times(tmp_path):
    data = H5Array("d.h5", "/fields/u", (NS, N, 3), "<f8")
    pts = H5Array("d.h5", "/mesh/points", (N, 3), "<f8")
    block = CellBlock("solids", "Hexahedron", H5Array("d.h5", "/mesh/hexes", (NE, 8), "<i8"))
    with pytest.raises(ValueError, match="has 4 steps, expected 3"):
        write_series(tmp_path / "d.xdmf", pts, block, [0.0, 1.0, 2.0],
                     [Series("u", data, "Node")])


def test_earlier_form_without_views_is_rewritten_once(tmp_path):
    _write(tmp_path)
    xdmf = tmp_path / "data.xdmf"
    calls = []
    assert has_views(xdmf) and not ensure_views(xdmf, lambda: calls.append(1))
    os.unlink(views_path(xdmf))                      # an XDMF file of the HyperSlab form
    assert ensure_views(xdmf, lambda: calls.append(1)) and calls == [1]
    remove_xdmf(xdmf)
    assert not xdmf.exists() and not views_path(xdmf).exists()
    assert not ensure_views(xdmf, lambda: calls.append(1)) and calls == [1]   # none: none
