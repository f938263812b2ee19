"""Run by ``pvbatch`` (ParaView's Python, not the project's): open XDMF files with every
XDMF reader and write what ParaView loaded to a JSON file.

Usage: ``pvbatch paraview_probe.py OUT.json FILE.xdmf [FILE.xdmf ...]``

For every file: the reader ParaView picks by default (``OpenDataFile``), and for each of
the legacy ``XDMFReader``, ``Xdmf3ReaderS`` and ``Xdmf3ReaderT``: the time step values and, at every
time step and for every leaf block, the block's point and cell counts and each point and
cell array's component count, per-component range and the tuples at four fixed indices
(first, one third, two thirds, last). Only ParaView's own modules are used here.
"""

import json
import sys

from paraview import servermanager
from paraview import simple as pv

READERS = ("XDMFReader", "Xdmf3ReaderS", "Xdmf3ReaderT")


def open_reader(kind, path):
    if kind == "XDMFReader":
        r = pv.XDMFReader(FileNames=[path])
        # the legacy reader loads only the arrays that are switched on
        r.PointArrayStatus = list(r.GetProperty("PointArrayInfo")[::2])
        r.CellArrayStatus = list(r.GetProperty("CellArrayInfo")[::2])
        return r
    return getattr(pv, kind)(FileName=[path])


def leaves(data):
    """(name, dataset) of every leaf of a composite dataset, or of the dataset itself."""
    if not data.IsA("vtkCompositeDataSet"):
        yield "0", data
        return
    it = data.NewIterator()
    it.InitTraversal()
    k = 0
    while not it.IsDoneWithTraversal():
        meta = it.GetCurrentMetaData() if it.HasCurrentMetaData() else None
        name = meta.Get(data.NAME()) if meta is not None and meta.Has(data.NAME()) else None
        yield name or str(k), it.GetCurrentDataObject()
        k += 1
        it.GoToNextItem()


def arrays(attributes, count):
    out = {}
    idx = sorted({0, count // 3, 2 * count // 3, max(count - 1, 0)}) if count else []
    for i in range(attributes.GetNumberOfArrays()):
        a = attributes.GetArray(i)
        if a is None:
            continue
        nc = a.GetNumberOfComponents()
        out[a.GetName()] = {
            "n_tuples": a.GetNumberOfTuples(), "n_components": nc,
            "range": [list(a.GetRange(c)) for c in range(nc)],
            "samples": {str(j): list(a.GetTuple(j)) for j in idx}}
    return out


def probe(kind, path):
    r = open_reader(kind, path)
    times = [float(t) for t in (r.TimestepValues or [])]
    steps = []
    for t in times or [None]:
        if t is None:
            r.UpdatePipeline()
        else:
            r.UpdatePipeline(t)
        blocks = {}
        for name, d in leaves(servermanager.Fetch(r)):
            blocks[name] = {"n_points": d.GetNumberOfPoints(), "n_cells": d.GetNumberOfCells(),
                            "point": arrays(d.GetPointData(), d.GetNumberOfPoints()),
                            "cell": arrays(d.GetCellData(), d.GetNumberOfCells())}
        steps.append({"time": t, "blocks": blocks})
    result = {"class": r.GetXMLName(), "times": times, "steps": steps}
    pv.Delete(r)
    return result


def main():
    out, files = sys.argv[1], sys.argv[2:]
    report = {"paraview": str(pv.GetParaViewVersion()), "files": {}}
    for path in files:
        report["files"][path] = {kind: probe(kind, path) for kind in READERS}
        default = pv.OpenDataFile(path)             # what File > Open picks
        report["files"][path]["default"] = default.GetXMLName()
        pv.Delete(default)
    with open(out, "w") as f:
        json.dump(report, f)


main()
