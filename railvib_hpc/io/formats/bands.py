"""The band cache of the band-sliced modal solve: ``<out>/bands``, its layout, writer, reader
and check.

The cache is a product of the ``modal`` stage (table name
:data:`~railvib_hpc.io.files.BAND_CACHE`, ``bands/index.json``): its index records its
provenance like every stage file, with the inputs digest of the case keys that change a
band (:data:`~railvib_hpc.io.products.STAGE_FILES`: the modes' keys without how many modes
up to which frequency are wanted, nor the band split), so raising ``modal.f_max`` keeps it
current and only adds bands. The modal stage reuses it through the one reuse helper
(:meth:`~railvib_hpc.io.stage_protocol.StageContext.reuse`: ``reusing ...`` or
``recomputing ...: <reason>``); a stale, foreign or corrupt index is never used.

Layout
------
``bands/index.json`` (JSON, written by rank 0 atomically, recorded)::

    counts       {repr(f_hz): N(f)}: the inertia counts (eigenvalues below f_hz)
    bands        [{index, lo_hz, hi_hz, shift_hz, file, n_below, n_modes, cover_lo_hz,
                   cover_hi_hz, stats, sha256}, ...]: the solved bands (``sha256``: the
                  band file's content digest, :func:`~railvib_hpc.io.digests.hash_file`)
    chain        {f_hz, bands: [{index, lo_hz, hi_hz, shift_hz}]}: the last merged plan
                 (None before a merge)
    provenance   as every stage file (:mod:`railvib_hpc.io.provenance`)
    complete     true (last)

``bands/band_<lo>_<hi>_<shift>.h5`` (one band, :func:`band_file_name`; collective write,
recorded)::

    modes        (n_dofs, m) float64: the band's own modes, by rows of the global DOFs
    eigenvalue   (m,) float64
    residual     (m,) float64: relative residuals
    attrs        lo_hz, hi_hz, shift_hz, n_below (N(shift)), stats (JSON), complete = 1

Check (:func:`check_band_cache`): the index's layout, and every band file it lists that
exists must be complete, of its band, with the content digest the index recorded (a
band file written again or copied in is foreign). A listed band file that no longer
exists is left out by the reader (:func:`read_index`) and solved again.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import DataError
from ..digests import file_digest
from ..files import BAND_INDEX_JSON

#: The fields of a band's entry in the index.
BAND_FIELDS = ("index", "lo_hz", "hi_hz", "shift_hz", "file", "n_below", "n_modes",
               "cover_lo_hz", "cover_hi_hz")


def band_file_name(band) -> str:
    """The file of a band (``lo_hz``, ``hi_hz``, ``shift_hz``) in the cache folder."""
    return f"band_{band.lo_hz:.6f}_{band.hi_hz:.6f}_{band.shift_hz:.6f}.h5"


def write_band(path: Path, comm, band, result, n_below: int, stats: dict) -> str:
    """The band's modes (n_dofs, m) by rows, eigenvalues and residuals (collective);
    returns the file's content digest (recorded)."""
    from ..atomic import write_h5
    from ..parallel_h5 import h5py_parallel_ok

    n_local, m = result.phi.shape
    # rank 0's statistics everywhere: parallel HDF5 needs identical attributes on all ranks
    stats = comm.bcast(stats, root=0)
    r0 = comm.exscan(n_local) or 0
    n = comm.allreduce(n_local)
    parallel = h5py_parallel_ok(comm)
    rows = [result.phi]
    if not parallel and comm.size > 1:
        parts = comm.gather(result.phi, root=0)
        rows = [np.concatenate(parts)] if comm.rank == 0 else [None]
        r0 = 0

    def fill(f, par: bool) -> None:
        d = f.create_dataset("modes", (n, m), "f8")
        f.create_dataset("eigenvalue", data=result.eigenvalues)
        f.create_dataset("residual", data=result.residuals)
        for k, v in (("lo_hz", band.lo_hz), ("hi_hz", band.hi_hz),
                     ("shift_hz", band.shift_hz), ("n_below", n_below)):
            f.attrs[k] = v
        f.attrs["stats"] = json.dumps(stats, default=float)
        if rows[0] is not None and rows[0].shape[0]:
            d[r0:r0 + rows[0].shape[0], :] = rows[0]

    # recorded: the index keeps its digest, so a band file written again is caught
    return write_h5(path, comm, fill, size_hint=8 * (n * m + 2 * m), parallel=parallel)


def read_band(path: Path, r0: int, r1: int) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalues of a band file and its rows ``r0:r1`` of the modes.

    Raises
    ------
    DataError
        For an incomplete file.
    """
    import h5py

    with h5py.File(path, "r") as f:
        if int(f.attrs.get("complete", 0)) != 1:
            raise DataError(f"{path} is incomplete: delete it and rerun")
        return f["eigenvalue"][()], f["modes"][r0:r1, :]


def empty_index() -> dict[str, Any]:
    """The index of an empty cache."""
    return {"counts": {}, "bands": [], "chain": None}


def read_index(path: Path) -> dict[str, Any]:
    """The index ``bands/index.json`` (checked: :func:`check_band_cache`): its counts,
    chain and the bands whose files exist (rank 0)."""
    doc = json.loads(Path(path).read_text())
    folder = Path(path).parent
    return {"counts": dict(doc.get("counts") or {}),
            "bands": [d for d in doc.get("bands") or [] if (folder / d["file"]).is_file()],
            "chain": doc.get("chain")}


def write_index(path: Path, index: Mapping[str, Any], prov: Mapping[str, Any] | None) -> None:
    """Write the index atomically with its provenance (None: a temporary cache, which is
    never reused) and record it (rank 0)."""
    from ..atomic import write_json

    write_json(path, {"counts": index["counts"], "bands": index["bands"],
                      "chain": index["chain"]}, prov)


def _band_problems(folder: Path, entry: Mapping[str, Any], full: bool) -> list[str]:
    """What is wrong with the band file of an index entry (none when it does not exist)."""
    import h5py

    name = f"{folder.name}/{entry['file']}"
    path = folder / entry["file"]
    if not path.is_file():
        return []
    if entry.get("sha256") and file_digest(path).sha256 != entry["sha256"]:
        return [f"{name} is not the band file it recorded (written again since)"]
    with h5py.File(path, "r") as f:
        if int(f.attrs.get("complete", 0)) != 1:
            return [f"{name} is incomplete"]
        got = [float(f.attrs.get(k, np.nan)) for k in ("lo_hz", "hi_hz", "shift_hz")]
        want = [float(entry[k]) for k in ("lo_hz", "hi_hz", "shift_hz")]
        if not np.allclose(got, want, rtol=1e-9, atol=0.0):
            return [f"{name} holds the band {got}, the index says {want}"]
        lam = f["eigenvalue"][()]
        if lam.shape != (int(entry["n_modes"]),) or f["modes"].shape[1] != lam.size:
            return [f"{name} has {lam.size} modes, the index says {entry['n_modes']}"]
        if full and not np.all(np.isfinite(lam)):
            return [f"{name} has non-finite eigenvalues"]
    return []


def check_band_cache(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                     ) -> list[str]:
    """``bands/index.json``: its layout, and every band file it lists that exists (complete,
    of its band, with the recorded content digest; with ``full`` finite eigenvalues)."""
    doc = json.loads(Path(path).read_text())
    counts, bands, chain = doc.get("counts"), doc.get("bands"), doc.get("chain", None)
    if not isinstance(counts, dict) or not isinstance(bands, list) \
            or not (chain is None or isinstance(chain, dict)):
        return ["its counts, bands or chain are missing or malformed"]
    out: list[str] = []
    for k, v in counts.items():
        if not float(k) >= 0 or int(v) < 0:
            out.append(f"its count {k}: {v} is not a count")
    for entry in bands:
        missing = [k for k in BAND_FIELDS if k not in entry]
        if missing:
            out.append(f"a band lacks {', '.join(missing)}")
            continue
        out += _band_problems(Path(path).parent, entry, full)
    return out


def index_path(folder: Path) -> Path:
    """The index of the cache in ``folder``."""
    return Path(folder) / BAND_INDEX_JSON
