"""The records and settings of a band-sliced eigensolve: the bounds its bands are
planned and merged with, one band's record (:class:`BandRecord`), the band cache of a run
(:class:`BandCache`) and the solve's settings (:class:`BandSettings`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from ..io.files import BAND_INDEX_JSON
from ..io.formats.bands import empty_index, write_index
from .bands import Band

#: A direction of the union of the bands' modes whose M-Gram eigenvalue is below this
#: fraction of the largest is a duplicate (two bands found the same mode): two copies
#: differing by e give an eigenvalue ~|e|^2 / 2, and |e| <= 2 rho / relgap <= 1e-4 for
#: residuals rho <= 1e-8 and relative gaps >= 2e-4, i.e. <= 5e-9; distinct M-orthogonal
#: modes give ~1.
DUPLICATE_GRAM = 1e-6


#: Converged modes beyond each band's edge that the Lanczos run must also deliver: the
#: proof that the band is complete (Krylov methods converge the largest |theta| first).
#: They are not kept (:func:`_trim`): the neighbouring band computes them.
EDGE_MARGIN = 2


#: Relative widening of a band's eigenvalue range when its modes are kept: an eigenvalue
#: on an edge is computed by both bands to ~1e-12 and may fall on either side; with the
#: overlap at least one band keeps it (two copies are merged by the Gram test).
EDGE_OVERLAP = 1e-6


#: Relative nudge of a shift that hits an eigenvalue (singular factor).
SHIFT_NUDGE = 1e-6


#: Basis size of a band's Lanczos run before a thick restart, in multiples of the band's
#: modes (as the single-shift stage's 3 n_modes): measured on the thesis model, 1006 modes
#: in 5 bands, 2 x needed 5-7 restarts per band and 7-9.5 right-hand sides per mode.
BASIS_FACTOR = 3


#: The most modes a band-sliced solve computes, as a share of the model's free DOFs. A mesh
#: resolves only the bottom of its spectrum: at ``mesh.min_elements_per_wavelength`` = 6,
#: Weyl's law for shear waves (two polarisations, N(f) = 8 pi V f^3 / (3 c_S^3)) puts
#: about 4 % of the elements, 1-2 % of the DOFs, below the resolved frequency. Above a
#: quarter of the DOFs the modes are mesh artefacts, the Weyl band plan misjudges the
#: saturated top of a discrete spectrum, and the merge's dense eigenproblem (cubic in the
#: count) dominates; a higher ``modal.f_max`` is refused before the bands are solved.
MAX_MODE_SHARE = 0.25


@dataclass
class BandRecord:
    """A solved band as cached in ``index.json`` (rank 0's view)."""

    band: Band
    file: str
    n_below: int
    n_modes: int
    cover_lo_hz: float
    cover_hi_hz: float
    stats: dict = field(default_factory=dict)
    #: the band file's content digest (the cache's check compares it)
    sha256: str = ""

    def to_json(self) -> dict:
        b = self.band
        return {"index": b.index, "lo_hz": b.lo_hz, "hi_hz": b.hi_hz, "shift_hz": b.shift_hz,
                "file": self.file, "n_below": self.n_below, "n_modes": self.n_modes,
                "cover_lo_hz": self.cover_lo_hz, "cover_hi_hz": self.cover_hi_hz,
                "stats": self.stats, "sha256": self.sha256}

    @classmethod
    def from_json(cls, d: dict) -> BandRecord:
        return cls(Band(int(d["index"]), float(d["lo_hz"]), float(d["hi_hz"]),
                        float(d["shift_hz"])), d["file"], int(d["n_below"]), int(d["n_modes"]),
                   float(d["cover_lo_hz"]), float(d["cover_hi_hz"]), dict(d.get("stats", {})),
                   str(d.get("sha256", "")))


def _same(a: float, b: float) -> bool:
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b), 1.0)


class BandCache:
    """The band cache in memory: the index of ``<out>/bands`` as the modal stage reused it
    (checked and current, on every rank; None: empty), saved by rank 0 with its provenance
    (:mod:`railvib_hpc.io.formats.bands`)."""

    def __init__(self, folder: Path, comm, index: dict | None = None,
                 provenance: dict | None = None):
        self.folder, self.comm, self.provenance = Path(folder), comm, provenance
        data = index or empty_index()
        self.counts: dict[float, int] = {float(k): int(v) for k, v in data["counts"].items()}
        self.bands = [BandRecord.from_json(d) for d in data["bands"]]
        self.chain = data.get("chain")

    def find(self, band: Band) -> BandRecord | None:
        for r in self.bands:
            if _same(r.band.lo_hz, band.lo_hz) and _same(r.band.hi_hz, band.hi_hz) and \
                    _same(r.band.shift_hz, band.shift_hz):
                return r
        return None

    def count(self, f_hz: float) -> int | None:
        for f, n in self.counts.items():
            if _same(f, f_hz):
                return n
        return None

    def save(self) -> None:
        """Rank 0 writes the index (call on every rank after the band files exist)."""
        if self.comm.rank == 0:
            data = {"counts": {repr(k): v for k, v in self.counts.items()},
                    "bands": [r.to_json() for r in self.bands], "chain": self.chain}
            write_index(self.folder / BAND_INDEX_JSON, data, self.provenance)
        self.comm.Barrier()


@dataclass
class BandSettings:
    """What :func:`solve_bands` needs besides the matrices."""

    f_max: float
    edges: list[float]
    band_modes: int
    groups: int
    band_only: int
    tol: float
    block_size: int
    max_restarts: int
    out_of_core: str
    cache_dir: Path
    #: the cache's index as the modal stage reused it (None: an empty cache)
    index: dict | None = None
    #: the provenance its index is written with (None: a temporary cache, never reused)
    provenance: dict | None = None
