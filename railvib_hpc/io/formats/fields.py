"""``fields.h5``: its layout and check (the fields of ``reconstruct`` and of ``transient``).

Layout (HDF5)::

    /time (ns,), /steps (ns,)             (step numbers in mbs.h5)
    /fields/{displacement,velocity,acceleration} (ns, n, 3)   float64 or float32
    /mesh/{points,hexes,hex_part}
    /stress/{von_mises,strain_eq} (n_sel, n_hex), /stress/time   (optional)
    attrs: the provenance, n_modes, n_extra (static-correction columns), stress_complete

``fields.xdmf`` / ``stress.xdmf``: temporal collections of per-step views
(``fields_views.h5``, ``stress_views.h5``; :mod:`railvib_hpc.io.xdmf`). The full-order
solution's ``fields.h5`` (``n_modes = 0``, ``solver = transient``) has this layout too.
Writer: the layout here (:func:`create_fields` creates every dataset,
:func:`set_fields_attrs`, :func:`fill_fields_mesh` the times and the mesh,
:func:`write_fields_xdmf`); the two writers that stream the fields of the distributed
solution into it, :func:`railvib_hpc.reconstruct.fields.reconstruct_fields` (modal
superposition) and :class:`railvib_hpc.transient.output.FieldWriter` (the full-order
run), compute the blocks. Reader: :class:`FieldsFile` (header, times, mesh, blocks of a
field over nodes, the stresses' currency). Check: :func:`check_fields` (shapes and times;
with ``full`` every field value is finite).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from ..xdmf import H5Array, Series, hex_mesh, write_series
from .checks import absent, h5_read, nonfinite

#: Names of the three fields, in the order they are computed and stored.
FIELD_NAMES = ("displacement", "velocity", "acceleration")

#: Steps per block when streaming ``fields.h5``.
_STEPS_PER_BLOCK = 16


def check_fields(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``fields.h5``: shapes and times; with ``full`` every field value is finite."""
    names = ("fields/displacement", "fields/velocity", "fields/acceleration")
    with h5_read(path) as f:
        missing = absent(f, ("time", "steps", *names, "mesh/points", "mesh/hexes"))
        if missing:
            return missing
        t = f["time"][()]
        out = nonfinite("time", t)
        if not out and np.any(np.diff(t) <= 0):
            out.append("time is not strictly increasing")
        n = f["mesh/points"].shape[0]
        for name in names:
            if f[name].shape != (len(t), n, 3):
                out.append(f"{name} has shape {f[name].shape}, expected ({len(t)}, {n}, 3)")
        if "stress" in f and int(f.attrs.get("stress_complete", 0)) == 1:
            for name in ("stress/von_mises", "stress/strain_eq"):
                if name in f:
                    out += nonfinite(name, f[name][()])
        if out or not full:
            return out
        for name in names:
            ds = f[name]
            for s0 in range(0, ds.shape[0], _STEPS_PER_BLOCK):
                out += nonfinite(name, ds[s0:s0 + _STEPS_PER_BLOCK])
                if out:
                    return out
    return out


def create_fields(f, ns: int, n: int, hexes_shape, hexes_dtype, part_dtype, dtype,
                  dcpl=None) -> dict:
    """Create every dataset of an open ``fields.h5`` at its global size (collective:
    identical on all ranks) for ``ns`` steps and ``n`` nodes; ``dcpl``: the fields'
    dataset creation property list (None: h5py's default). Returns them by name
    (``time``, ``steps``, the :data:`FIELD_NAMES`, ``points``, ``hexes``, ``hex_part``)."""
    hexes_shape = tuple(hexes_shape)
    out = {"time": f.create_dataset("time", (ns,), "f8"),
           "steps": f.create_dataset("steps", (ns,), "i8")}
    g = f.create_group("fields")
    for name in FIELD_NAMES:                                          # contiguous layout
        out[name] = (g.create_dataset(name, (ns, n, 3), dtype) if dcpl is None
                     else g.create_dataset(name, (ns, n, 3), dtype, dcpl=dcpl))
    gm = f.create_group("mesh")
    out["points"] = gm.create_dataset("points", (n, 3), "f8")
    out["hexes"] = gm.create_dataset("hexes", hexes_shape, np.dtype(hexes_dtype))
    out["hex_part"] = gm.create_dataset("hex_part", (hexes_shape[0],), np.dtype(part_dtype))
    return out


def set_fields_attrs(f, *, n_modes: int, n_extra: int, float32: bool, block_steps: int,
                     modes_file: str, **more) -> None:
    """The root attributes of ``fields.h5`` (``more``: the writer's own, after them)."""
    f.attrs["n_modes"] = n_modes
    f.attrs["n_extra"] = n_extra
    f.attrs["float32"] = int(bool(float32))
    f.attrs["block_steps"] = block_steps
    f.attrs["modes_file"] = modes_file
    for key, value in more.items():
        f.attrs[key] = value


def fill_fields_mesh(dsets: dict, times, steps, points, hexes, hex_part) -> None:
    """Rank 0: the times, step numbers and mesh arrays into the datasets of
    :func:`create_fields` (empty mesh arrays are left alone)."""
    for key, value in (("points", points), ("hexes", hexes), ("hex_part", hex_part)):
        if dsets[key].size:
            dsets[key][...] = value
    dsets["time"][...] = times
    dsets["steps"][...] = steps


def write_fields_xdmf(h5_path: str | os.PathLike, name: str | None = None) -> Path:
    """Write ``fields.xdmf`` (+ ``fields_views.h5``) next to ``h5_path``: one grid per
    stored step with the displacement, velocity and acceleration (serial).

    Parameters
    ----------
    h5_path
        A ``fields.h5`` (complete, or the temporary file that becomes it).
    name
        File name the XDMF refers to (default: ``h5_path``'s name).

    Returns
    -------
    Path
        The XDMF file.
    """
    h5_path = Path(h5_path)
    name = name or h5_path.name
    return write_series_xdmf(h5_path, name, "time", "fields", FIELD_NAMES, "Node",
                             h5_path.with_name(Path(name).stem + ".xdmf"))


def write_series_xdmf(h5_path: Path, name: str, time: str, group: str,
                      datasets: Sequence[str], center: str, xdmf: Path) -> Path:
    """Write ``xdmf`` (+ its views file) of the hexahedral mesh of ``h5_path`` with the
    datasets ``/<group>/<datasets>`` at the times ``/<time>`` as ``center`` data ("Node" or
    "Cell"), one grid per time; ``name`` is the file name the XDMF refers to (serial).
    Serves ``fields.xdmf`` and ``stress.xdmf`` (:mod:`railvib_hpc.reconstruct.stress`)."""
    import h5py

    with h5py.File(h5_path, "r") as f:
        points, block = hex_mesh(f, name)
        times = f[time][()]
        series = [Series(k, H5Array.of(f, f"/{group}/{k}", name), center) for k in datasets]
    write_series(xdmf, points, block, times, series)
    return xdmf


class FieldsFile:
    """The reader of ``fields.h5`` (rank 0; each method opens the file for itself and
    reads plainly: ``OSError``, ``KeyError`` of h5py on a broken file)."""

    def __init__(self, path: Path):
        self.path = Path(path)

    def _h5(self):
        import h5py

        return h5py.File(self.path, "r")

    def complete(self) -> bool:
        """Whether the file is marked complete."""
        with self._h5() as f:
            return int(f.attrs.get("complete", 0)) == 1

    def header(self) -> tuple[int, np.ndarray, tuple, tuple]:
        """``complete`` (the attribute), the times, the fields' and the hexahedra's shapes."""
        with self._h5() as f:
            return (int(f.attrs.get("complete", 0)), f["time"][()],
                    f["fields/displacement"].shape, f["mesh/hexes"].shape)

    def times(self) -> np.ndarray:
        """``/time`` (ns,)."""
        with self._h5() as f:
            return f["time"][()]

    def n_hexes(self) -> int:
        """The number of hexahedra of ``/mesh``."""
        with self._h5() as f:
            return f["mesh/hexes"].shape[0]

    def mesh(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``/mesh/points``, ``hexes``, ``hex_part``."""
        with self._h5() as f:
            return f["mesh/points"][()], f["mesh/hexes"][()], f["mesh/hex_part"][()]

    def blocks(self, name: str, nodes: np.ndarray, steps: int) -> Iterator[np.ndarray]:
        """``/fields/<name>`` at the (sorted, unique) ``nodes``, ``steps`` steps at a time
        (each block (b, len(nodes), 3))."""
        with self._h5() as f:
            d = f["fields/" + name]
            lo, hi = int(nodes.min()), int(nodes.max()) + 1
            for s0 in range(0, d.shape[0], steps):
                yield d[s0:s0 + steps, lo:hi, :][:, nodes - lo, :]

    def stress_current(self, key: str) -> bool:
        """Whether ``/stress`` is complete and has the inputs digest ``key``."""
        def attr(obj, name: str, default=None):
            v = obj.attrs.get(name, default)
            return v.decode() if isinstance(v, bytes) else v

        with self._h5() as f:
            return ("stress" in f and int(attr(f, "stress_complete", 0)) == 1
                    and attr(f["stress"], "inputs_sha256") == key)
