"""XDMF files for ParaView: the one writer of XDMF text in railvib-hpc.

Every ``*.xdmf`` file (mesh, modes, fields, stresses) is built here from
:class:`H5Array` descriptions of HDF5 datasets. Nothing else in the package writes XDMF.

Which XDMF form the readers load
--------------------------------
ParaView offers two XDMF readers: the legacy "XDMF Reader" (``XDMFReader``, XDMF 2
library) and the XDMF 3 readers ``Xdmf3ReaderS``/``Xdmf3ReaderT``. Measured with
``pvbatch`` of ParaView 5.11 (Debian 12), on ``modes.xdmf`` of the coarse thesis model:

============================================================  ==========  ===========
form of the per-step DataItem                                 legacy      XDMF 3
============================================================  ==========  ===========
``ItemType="HyperSlab"`` of the (steps, n, 3) dataset         loads       no data [1]
``ItemType="Function"`` around that HyperSlab                 loads       no data [1]
XDMF 3 content ``file.h5:/ds|start:stride:count:dims``        fails [2]   loads
plain ``Format="HDF"`` item of an (n, 3) dataset              loads       loads
plain item of an HDF5 *virtual* dataset (n, 3) [3]            loads       loads
============================================================  ==========  ===========

[1] the XDMF 3 library makes a HyperSlab or Function a *reference* whose number type is
unknown until it is read, and ``vtkXdmf3DataSet`` asks for the type before reading:
"Skipping unrecognized array type [None]"; the arrays are listed but never loaded.
[2] the legacy library takes everything after the colon as the dataset name.
[3] an HDF5 1.10+ virtual dataset (VDS) that maps one row of the big dataset.

So every array is a plain ``Format="HDF"`` DataItem of a dataset of exactly the
DataItem's shape. Time series are stored as one (steps, ...) dataset per quantity
(``modes.h5``, ``fields.h5``, fast to write collectively and read by the other stages);
their per-step arrays are virtual datasets in a small sidecar file next to the XDMF
file, ``<stem>_views.h5`` (``modes_views.h5``, ``fields_views.h5``,
``stress_views.h5``): ``/<dataset path>/<step:06d>`` maps row ``step`` of
``<data file>:<dataset path>`` (no data is copied; a few hundred bytes per step). The
source file is named relative to the sidecar, so the folder can be moved or copied as a
whole. A view whose source is missing reads as NaN (its fill value), never as a
plausible zero field.

Example
-------
>>> import numpy as np
>>> pts = H5Array("mesh.h5", "/mesh/points", (8, 3), "<f8")
>>> hexes = H5Array("mesh.h5", "/mesh/hexes", (1, 8), "<i8")
>>> text = mesh_document(pts, [CellBlock("solids", "Hexahedron", hexes)])
>>> '<DataItem Dimensions="8 3" NumberType="Float" Precision="8" Format="HDF">' in text
True
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .atomic import atomic_file, write_text

__all__ = [
    "CellBlock",
    "H5Array",
    "Series",
    "ensure_views",
    "has_views",
    "hex_mesh",
    "mesh_document",
    "read_xdmf",
    "remove_xdmf",
    "series_document",
    "views_path",
    "write_series",
]

#: XDMF number types of the numpy dtype kinds.
_NUMBER_TYPE = {"f": "Float", "i": "Int", "u": "UInt"}
#: Nodes per element of the XDMF topologies used here.
_NODES_PER_ELEMENT = {"Hexahedron": 8, "Polyline": 2}


@dataclass(frozen=True)
class H5Array:
    """An HDF5 dataset as an XDMF DataItem refers to it.

    Parameters
    ----------
    file
        HDF5 file name relative to the XDMF file (the same folder).
    path
        Absolute dataset path inside the file, e.g. ``/mesh/points``.
    shape
        Dataset shape.
    dtype
        numpy dtype (string or dtype) of the dataset.
    """

    file: str
    path: str
    shape: tuple[int, ...]
    dtype: str

    @classmethod
    def of(cls, f, path: str, file: str | None = None) -> H5Array:
        """The dataset ``path`` of the open h5py file ``f`` (named ``file``, default: its
        own file name)."""
        d = f[path]
        return cls(file or Path(f.filename).name, "/" + path.strip("/"), tuple(d.shape),
                   d.dtype.str)

    def item(self) -> ET.Element:
        """The ``<DataItem Format="HDF">`` element."""
        dt = np.dtype(self.dtype)
        if dt.kind not in _NUMBER_TYPE:
            raise ValueError(f"{self.file}:{self.path}: dtype {dt} has no XDMF number type")
        el = ET.Element("DataItem", {
            "Dimensions": " ".join(str(int(d)) for d in self.shape),
            "NumberType": _NUMBER_TYPE[dt.kind], "Precision": str(dt.itemsize),
            "Format": "HDF"})
        el.text = f"{self.file}:{self.path}"
        return el


@dataclass(frozen=True)
class CellBlock:
    """Cells of one topology with an optional ``part_id`` cell attribute.

    Parameters
    ----------
    name
        Grid name in mesh files.
    topology
        ``"Hexahedron"`` (8 nodes, VTK order) or ``"Polyline"`` (2-node lines).
    cells
        (ne, nodes per element) connectivity.
    part_id
        (ne,) part id of every cell, or None.
    """

    name: str
    topology: str
    cells: H5Array
    part_id: H5Array | None = None

    def elements(self) -> list[ET.Element]:
        """The ``Topology`` element and the ``part_id`` attribute (if any)."""
        npe = _NODES_PER_ELEMENT[self.topology]
        ne = self.cells.shape[0]
        if tuple(self.cells.shape) != (ne, npe):
            raise ValueError(f"{self.topology} cells must be ({ne}, {npe}), "
                             f"got {self.cells.shape}")
        attrs = {"TopologyType": self.topology, "NumberOfElements": str(ne)}
        if self.topology == "Polyline":
            attrs["NodesPerElement"] = str(npe)
        topo = ET.Element("Topology", attrs)
        topo.append(self.cells.item())
        out = [topo]
        if self.part_id is not None:
            out.append(_attribute("part_id", "Cell", self.part_id))
        return out


@dataclass(frozen=True)
class Series:
    """A quantity stored as one (steps, ...) dataset, shown as one attribute per step.

    Parameters
    ----------
    name
        Attribute name in ParaView.
    data
        The (steps, n, 3) node vectors or (steps, ne) cell scalars.
    center
        ``"Node"`` or ``"Cell"``.
    """

    name: str
    data: H5Array
    center: str

    def view(self, views_file: str, k: int) -> H5Array:
        """The per-step view ``k`` in the sidecar ``views_file``."""
        return H5Array(views_file, view_name(self.data.path, k), tuple(self.data.shape[1:]),
                       self.data.dtype)


def hex_mesh(f, file: str | None = None) -> tuple[H5Array, CellBlock]:
    """Points and hexahedra (with ``part_id``) of ``/mesh`` in the open h5py file ``f``."""
    return (H5Array.of(f, "/mesh/points", file),
            CellBlock("solids", "Hexahedron", H5Array.of(f, "/mesh/hexes", file),
                      H5Array.of(f, "/mesh/hex_part", file)))


def view_name(dataset: str, k: int) -> str:
    """Path of the view of row ``k`` of ``dataset`` in a sidecar file."""
    return f"/{dataset.strip('/')}/{k:06d}"


def views_path(xdmf_path: str | os.PathLike) -> Path:
    """The sidecar file of the per-step views of an XDMF file: ``<stem>_views.h5``."""
    xdmf_path = Path(xdmf_path)
    return xdmf_path.with_name(f"{xdmf_path.stem}_views.h5")


def _attribute(name: str, center: str, data: H5Array) -> ET.Element:
    if center not in ("Node", "Cell"):
        raise ValueError(f"attribute {name}: center must be Node or Cell, got {center!r}")
    kind = "Vector" if center == "Node" and len(data.shape) == 2 and data.shape[1] == 3 \
        else "Scalar"
    el = ET.Element("Attribute", {"Name": name, "AttributeType": kind, "Center": center})
    el.append(data.item())
    return el


def _geometry(points: H5Array) -> ET.Element:
    if len(points.shape) != 2 or points.shape[1] != 3:
        raise ValueError(f"points must be (n, 3), got {points.shape}")
    geo = ET.Element("Geometry", {"GeometryType": "XYZ"})
    geo.append(points.item())
    return geo


def _grid(name: str, points: H5Array, block: CellBlock,
          attributes: Sequence[tuple[str, str, H5Array]] = (),
          time: float | None = None) -> ET.Element:
    grid = ET.Element("Grid", {"Name": name, "GridType": "Uniform"})
    if time is not None:
        ET.SubElement(grid, "Time", {"Value": repr(float(time))})
    topo, *part = block.elements()
    grid.append(topo)
    grid.append(_geometry(points))
    grid.extend(part)
    for attr_name, center, data in attributes:
        grid.append(_attribute(attr_name, center, data))
    return grid


def _document(collection: ET.Element) -> str:
    root = ET.Element("Xdmf", {"Version": "3.0"})
    ET.SubElement(root, "Domain").append(collection)
    ET.indent(root, space="  ")
    return '<?xml version="1.0" ?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def mesh_document(points: H5Array, blocks: Sequence[CellBlock],
                  name: str = "railvib_model") -> str:
    """XDMF text of a mesh: a spatial collection of one grid per non-empty cell block.

    Parameters
    ----------
    points
        (n, 3) node coordinates, shared by the blocks.
    blocks
        Cell blocks (e.g. hexahedra, beams and pads); blocks without cells are left out.
    name
        Name of the collection.
    """
    coll = ET.Element("Grid", {"Name": name, "GridType": "Collection",
                               "CollectionType": "Spatial"})
    for block in blocks:
        if block.cells.shape[0] > 0:
            coll.append(_grid(block.name, points, block))
    return _document(coll)


def series_document(name: str, points: H5Array, block: CellBlock, times: Sequence[float],
                    series: Sequence[Series], views_file: str,
                    grid_names: Sequence[str] | None = None) -> str:
    """XDMF text of a time series: a temporal collection of one grid per step.

    Parameters
    ----------
    name
        Name of the collection (and prefix of the grid names ``<name>_<k>``).
    points, block
        The mesh every step is shown on.
    times
        (ns,) time values (for modes: the mode numbers).
    series
        The quantities; each attribute of step ``k`` is the view ``k`` in ``views_file``.
    views_file
        Name of the sidecar file of views (relative to the XDMF file).
    grid_names
        Names of the steps' grids (default ``<name>_<k>``).
    """
    ns = len(times)
    for s in series:
        if s.data.shape[0] != ns:
            raise ValueError(f"{s.name}: {s.data.path} has {s.data.shape[0]} steps, "
                             f"expected {ns}")
    names = list(grid_names) if grid_names is not None else [f"{name}_{k}" for k in range(ns)]
    coll = ET.Element("Grid", {"Name": name, "GridType": "Collection",
                               "CollectionType": "Temporal"})
    for k, tk in enumerate(times):
        coll.append(_grid(names[k], points, block,
                          [(s.name, s.center, s.view(views_file, k)) for s in series], tk))
    return _document(coll)


def _write_views(path: Path, series: Sequence[Series]) -> None:
    """Write the sidecar of per-step virtual datasets (atomic; sources are not opened)."""
    import h5py

    with atomic_file(path) as tmp, h5py.File(tmp, "w") as f:
        f.attrs["about"] = ("per-step views (HDF5 virtual datasets) of the time series in "
                            "the data file, for ParaView's XDMF readers; no data of its own")
        for s in series:
            shape, dt = tuple(s.data.shape), np.dtype(s.data.dtype)
            source = h5py.VirtualSource(s.data.file, s.data.path, shape=shape, dtype=dt)
            fill = np.nan if dt.kind == "f" else 0
            for k in range(shape[0]):
                layout = h5py.VirtualLayout(shape=shape[1:], dtype=dt)
                layout[...] = source[k]
                f.create_virtual_dataset(view_name(s.data.path, k), layout, fillvalue=fill)


def write_series(xdmf_path: str | os.PathLike, points: H5Array, block: CellBlock,
                 times: Sequence[float], series: Sequence[Series],
                 grid_names: Sequence[str] | None = None) -> Path:
    """Write a time-series XDMF file and its sidecar of views (serial; atomic).

    The sidecar ``<stem>_views.h5`` is written first, the XDMF file last, so an XDMF
    file never refers to views that do not exist. The data file need not exist yet
    (nor have its final name): the views name it and are resolved when read.

    Parameters
    ----------
    xdmf_path
        The XDMF file to write.
    points, block, times, series, grid_names
        See :func:`series_document`; ``series[i].data.file`` is the data file's name
        relative to ``xdmf_path``'s folder.

    Returns
    -------
    Path
        The sidecar file.
    """
    xdmf_path = Path(xdmf_path)
    sidecar = views_path(xdmf_path)
    _write_views(sidecar, series)
    write_text(xdmf_path, series_document(xdmf_path.stem, points, block, times, series,
                                                 sidecar.name, grid_names))
    return sidecar


def has_views(xdmf_path: str | os.PathLike) -> bool:
    """True when the XDMF file and its sidecar of views exist (False for files of the
    earlier HyperSlab form, which has no sidecar: rewrite them)."""
    return Path(xdmf_path).is_file() and views_path(xdmf_path).is_file()


def ensure_views(xdmf_path: str | os.PathLike, write: Callable[[], object]) -> bool:
    """Call ``write()`` when ``xdmf_path`` exists without its sidecar of views: an XDMF file
    of the earlier HyperSlab form, which ParaView's XDMF 3 reader shows without data. For
    reused data files; where there is no XDMF file (e.g. a study variant's linked
    ``modes.h5``) none is created. Returns True when it was rewritten."""
    if not Path(xdmf_path).is_file() or views_path(xdmf_path).is_file():
        return False
    write()
    return True


def remove_xdmf(xdmf_path: str | os.PathLike) -> None:
    """Delete an XDMF file and its sidecar of views (whichever exist)."""
    xdmf_path = Path(xdmf_path)
    xdmf_path.unlink(missing_ok=True)
    views_path(xdmf_path).unlink(missing_ok=True)


def read_xdmf(xdmf_path: str | os.PathLike) -> list[dict]:
    """Read an XDMF file of ours through h5py, as a reader sees it (for checks and scripts).

    Everything is loaded into memory: meant for checks of small outputs.

    Returns
    -------
    list of dict
        One entry per uniform grid: ``name``, ``time`` (or None), ``topology``,
        ``n_cells``, ``points`` (n, 3), ``cells`` (ne, k) and ``attributes``
        ``{name: (center, array)}``. Every DataItem is read from its HDF5 file and checked
        against its declared dimensions and precision (``ValueError`` otherwise).
    """
    import h5py

    xdmf_path = Path(xdmf_path)
    root = ET.parse(xdmf_path).getroot()
    files: dict[str, h5py.File] = {}
    cache: dict[tuple[str, str], np.ndarray] = {}   # the mesh arrays recur in every grid

    def load(item: ET.Element) -> np.ndarray:
        if item.get("Format") != "HDF" or item.get("ItemType", "Uniform") != "Uniform":
            raise ValueError(f"{xdmf_path}: unsupported DataItem {item.attrib}")
        name, dset = item.text.strip().split(":", 1)
        if name not in files:
            files[name] = h5py.File(xdmf_path.parent / name, "r")
        if (name, dset) not in cache:
            cache[name, dset] = files[name][dset][()]
        data = cache[name, dset]
        dims = tuple(int(d) for d in item.get("Dimensions").split())
        if data.shape != dims or data.dtype.itemsize != int(item.get("Precision", 4)) or \
                _NUMBER_TYPE.get(data.dtype.kind) != item.get("NumberType", "Float"):
            raise ValueError(f"{xdmf_path}: {name}:{dset} is {data.dtype}{data.shape}, the "
                             f"DataItem says {item.attrib}")
        return data

    out = []
    try:
        for grid in root.iter("Grid"):
            if grid.get("GridType") != "Uniform":
                continue
            topo = grid.find("Topology")
            time = grid.find("Time")
            out.append({
                "name": grid.get("Name"),
                "time": None if time is None else float(time.get("Value")),
                "topology": topo.get("TopologyType"),
                "n_cells": int(topo.get("NumberOfElements")),
                "cells": load(topo.find("DataItem")),
                "points": load(grid.find("Geometry/DataItem")),
                "attributes": {a.get("Name"): (a.get("Center"), load(a.find("DataItem")))
                               for a in grid.findall("Attribute")},
            })
    finally:
        for f in files.values():
            f.close()
    return out
