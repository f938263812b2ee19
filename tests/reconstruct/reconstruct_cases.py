"""Inputs for the reconstruct tests: synthetic meshes, modes files, mbs.h5 and static bases."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

from railvib_hpc.mesh.model import Mesh
from railvib_hpc.schema import PART_ID

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
#: Overrides of the coarse real model (about 12 000 nodes) and its number of modes.
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=8"]
N_MODES = 8


def shared_dir(comm=MPI.COMM_WORLD) -> Path:
    """A new temporary folder, the same on every rank (collective)."""
    path = tempfile.mkdtemp(prefix="railvib-reconstruct-") if comm.rank == 0 else None
    return Path(comm.bcast(path, root=0))


def remove_dir(path: Path, comm=MPI.COMM_WORLD) -> None:
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)


def box_mesh(nx: int = 3, ny: int = 2, nz: int = 2, distort: float = 0.15) -> Mesh:
    """A distorted structured block of hexahedra (general trilinear elements), two parts.

    Interior nodes are moved by a smooth field so no element is a parallelepiped; the
    lower half of the elements is subgrade, the upper half slab (concrete).
    """
    xs, ys, zs = (np.linspace(0.0, float(k), k + 1) for k in (nx, ny, nz))
    X, Y, Z = np.meshgrid(xs, ys, zs, indexing="ij")
    pts = np.c_[X.ravel(), Y.ravel(), Z.ravel()]
    inner = ((pts > 0) & (pts < [nx, ny, nz])).all(axis=1)
    shift = distort * np.c_[np.sin(3.1 * pts[:, 1] + 1.3 * pts[:, 2]),
                            np.cos(2.3 * pts[:, 0] - 0.7 * pts[:, 2]),
                            np.sin(1.7 * pts[:, 0] + 2.9 * pts[:, 1])]
    pts[inner] += shift[inner]

    def nid(i, j, k):
        return (i * (ny + 1) + j) * (nz + 1) + k

    hexes = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                hexes.append([nid(i, j, k), nid(i + 1, j, k), nid(i + 1, j + 1, k),
                              nid(i, j + 1, k), nid(i, j, k + 1), nid(i + 1, j, k + 1),
                              nid(i + 1, j + 1, k + 1), nid(i, j + 1, k + 1)])
    hexes = np.array(hexes, dtype=np.int64)
    zc = pts[hexes, 2].mean(axis=1)
    part = np.where(zc < nz / 2, PART_ID["subgrade"], PART_ID["slab"]).astype(np.int32)
    return Mesh(points=pts, hexes=hexes, hex_part=part, lines=np.zeros((0, 2), np.int64),
                line_part=np.zeros(0, np.int32), node_sets={"bottom": np.flatnonzero(
                    pts[:, 2] == 0.0)}, probes={"centre": (nx / 2, ny / 2, nz / 2)},
                probe_roles={"centre": "floor"})


def write_synthetic_modes(path: Path, mesh: Mesh, translation: np.ndarray) -> None:
    """A complete ``modes.h5`` (real writer, one rank) with given mode shapes (m, n, 3)."""
    from railvib_hpc.io.formats.modes import write_modes

    m, n = translation.shape[0], mesh.n_nodes
    write_modes(Path(path), MPI.COMM_SELF, mesh, slice(0, n),
                (2 * np.pi * np.arange(1.0, m + 1)) ** 2, translation, np.zeros((m, 0, 3)),
                np.zeros(0, np.int64), slice(0, 0), np.ones(n), np.zeros((n, 6), np.int64),
                {"inputs_sha256": "synthetic"})


def histories(nt: int, m: int, seed: int = 0, dt: float = 1e-3):
    """Random modal histories ``t, q, q_dot, q_ddot``."""
    rng = np.random.default_rng(seed)
    t = 0.1 + dt * np.arange(nt)
    return (t,) + tuple(rng.standard_normal((nt, m)) * s for s in (1e-4, 1e-2, 1.0))


def write_static_basis(path: Path, n: int, k: int, seed: int = 1) -> np.ndarray:
    """A static-correction basis file ``/basis`` (k, n, 3), complete; returns the basis."""
    basis = np.random.default_rng(seed).standard_normal((k, n, 3)) * 1e-3
    with h5py.File(path, "w") as f:
        f.create_dataset("basis", data=basis)
        f.attrs["complete"] = 1
        f.attrs["inputs_sha256"] = f"static-{seed}"
    return basis


def write_mbs(path: Path, t, q, q_dot, q_ddot, static: dict | None = None,
              complete: int = 1, digest: str = "mbs-1") -> None:
    """An ``mbs.h5`` as the multibody stage writes it (only what reconstruct reads)."""
    with h5py.File(path, "w") as f:
        f.create_dataset("time", data=t)
        g = f.create_group("modal")
        for name, a in (("q", q), ("q_dot", q_dot), ("q_ddot", q_ddot)):
            g.create_dataset(name, data=a)
        if static is not None:
            s = f.create_group("static")
            s.attrs["basis_file"] = static["basis_file"]
            s.attrs["basis"] = static["basis"]
            for name in ("g", "g_dot", "g_ddot"):
                s.create_dataset(name, data=static[name])
        f.attrs["complete"] = complete
        f.attrs["inputs_sha256"] = digest


def read_modes(path: Path, m: int) -> tuple[np.ndarray, dict]:
    """Serial reference: the first ``m`` mode shapes (m, n, 3) and the mesh arrays."""
    with h5py.File(path, "r") as f:
        return f["modes/translation"][:m], {k: f["mesh/" + k][()] for k in
                                            ("points", "hexes", "hex_part")}


def superpose(phi: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Serial reference ``(nt, n, 3) = q @ phi`` with numpy."""
    return np.einsum("tm,mni->tni", q, phi)


def relative_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(b).max(), 1e-300))
