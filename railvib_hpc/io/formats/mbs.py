"""``mbs.h5``: its layout and check (the multibody stage's passage in modal coordinates).

Layout (HDF5, rank 0)::

    /time
    /wheels/{x, contact_force, penetration, rail_displacement, wheel_height, rail_index}
    /vehicle/{y, y_dot, y_ddot}        (DOF names in an attribute)
    /modal/{q, q_dot, q_ddot, omega, zeta}   at every stored step (mbs.store_every)
    /static/{g, g_dot, g_ddot}         with the static correction: the rail-DOF loads
                                       g = V p of the residual modes' coordinates,
    /static/{q_shift, q_shift_dot, q_shift_ddot}, /static/{residual_omega, residual_vectors}
    attrs: the provenance and stats (JSON: steps, time step, contact forces per wheel, rail
           deflection, timings)

Writer: :func:`write_mbs_h5` (of the passage duck-typed and arrays; the multibody stage,
:mod:`railvib_hpc.mbs.stage`, forms them). Reader: :class:`MbsFile` (every reader of the
file: the reconstruction's validated window of the histories, the time step, the contact
forces, the summary of the report, the modal accelerations). Check: :func:`check_mbs`,
:func:`check_mbs_arrays` (the histories in memory, before the write). Plausibility bound
of the modal coordinates (Duhamel): with ``psi_i`` the largest modal amplitude at the
rails (translation plus element length times rotation, :func:`rail_amplitude`), ``F`` the
sum of the peak wheel forces, ``B_i = psi_i F / omega_i^2`` the static modal deflection
and ``D_i = 1 + omega_i T`` the growth bound over the duration ``T`` (exact for the
undamped oscillator started at static equilibrium, damping only lowers it):
``|q_i| <= K B_i D_i``, ``|q_dot_i| <= K B_i omega_i D_i``,
``|q_ddot_i| <= K B_i omega_i^2 (1 + 2 D_i)`` with :data:`MODAL_RESPONSE_FACTOR`
``K = 10``; contact forces within
:data:`~railvib_hpc.io.formats.checks.CONTACT_FORCE_FACTOR` x the static wheel load.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ...errors import UserError
from ..atomic import write_h5
from ..files import MBS_H5, MODES_H5, STATIC_H5
from .checks import (
    CONTACT_FORCE_FACTOR,
    absent,
    exceeds,
    h5_read,
    nonfinite,
    open_input,
    static_wheel_load,
    text_attr,
)

#: Safety factor on the Duhamel bounds of the modal coordinates.
MODAL_RESPONSE_FACTOR = 10.0


def rail_amplitude(modes_path: Path, m: int) -> np.ndarray:
    """(m,) largest modal amplitude at the rails: translation plus element length times
    rotation (what a wheel force can excite; module notes)."""
    with h5_read(modes_path) as f:
        rails = f["mesh/rail_nodes"][()].reshape(-1)
        rails = np.unique(rails[rails >= 0])
        if rails.size == 0:
            return np.zeros(m)
        tr = f["modes/translation"][:m, rails, :]
        rot_nodes = f["mesh/rotation_nodes"][()]
        pos = np.searchsorted(rot_nodes, rails)
        ok = (pos < len(rot_nodes)) & (rot_nodes[np.minimum(pos, len(rot_nodes) - 1)] == rails)
        rot = f["modes/rotation"][:m, np.unique(pos[ok]), :] if ok.any() else np.zeros((m, 1, 3))
        x = np.sort(f["mesh/points"][rails, 0])
    h = float(np.diff(x).max()) if x.size > 1 else 0.0
    return (np.linalg.norm(tr, axis=2).max(axis=1)
            + h * np.linalg.norm(rot, axis=2).max(axis=1))


def check_mbs_arrays(t, contact_force, q, q_dot, q_ddot, omega, static_load: float,
                     psi: np.ndarray | None, others: Mapping[str, np.ndarray] | None = None
                     ) -> list[str]:
    """Histories of a multibody run: finite, contact forces and modal coordinates bounded.

    Parameters
    ----------
    t, contact_force, q, q_dot, q_ddot, omega
        As stored in ``mbs.h5``.
    static_load
        Largest static wheel load of the case [N] (0: not known, no force bound).
    psi
        (m,) rail amplitude of the modes (:func:`rail_amplitude`); None: no modal bound.
    others
        More arrays to check for finite values (name: array).
    """
    out = []
    for name, a in (("time", t), ("wheels/contact_force", contact_force), ("modal/q", q),
                    ("modal/q_dot", q_dot), ("modal/q_ddot", q_ddot), ("modal/omega", omega),
                    *(others or {}).items()):
        out += nonfinite(name, np.asarray(a))
    if out:
        return out
    t = np.asarray(t)
    if t.ndim != 1 or t.size == 0 or np.any(np.diff(t) <= 0):
        return ["time must be non-empty and strictly increasing"]
    force = np.asarray(contact_force, dtype=float)
    if static_load > 0:
        out += exceeds("wheels/contact_force", force, CONTACT_FORCE_FACTOR * static_load,
                       f"{CONTACT_FORCE_FACTOR:g} x the static wheel load {static_load:.4g} N")
    om = np.asarray(omega, dtype=float)
    if np.any(om <= 0):
        out.append("modal/omega must be > 0")
    if out or psi is None or force.size == 0:
        return out
    f_tot = float(np.abs(force).max(axis=0).sum())
    m = np.shape(q)[1]
    om, psi = om[:m], np.asarray(psi, dtype=float)[:m]
    b = MODAL_RESPONSE_FACTOR * psi * f_tot / om**2
    d = 1.0 + om * float(t[-1] - t[0])
    what = "Duhamel bound of the passage"
    out += exceeds("modal/q", np.asarray(q), b * d, what)
    out += exceeds("modal/q_dot", np.asarray(q_dot), b * om * d, what)
    out += exceeds("modal/q_ddot", np.asarray(q_ddot), b * om**2 * (1 + 2 * d), what)
    return out


def check_mbs(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
              ) -> list[str]:
    """``mbs.h5`` (always completely: it is small). ``context``: ``static_wheel_load`` [N],
    ``modes_path`` (for the modal bounds)."""
    context = context or {}
    with h5_read(path) as f:
        missing = absent(f, ("time", "wheels/x", "wheels/contact_force", "modal/q",
                            "modal/q_dot", "modal/q_ddot", "modal/omega", "modal/zeta"))
        if missing:
            return missing
        load = static_wheel_load(f, context)
        q = f["modal/q"][()]
        psi = None
        modes = context.get("modes_path")
        if modes is not None and Path(modes).exists():
            try:
                psi = rail_amplitude(Path(modes), q.shape[1])
            except (OSError, KeyError, ValueError, IndexError):
                psi = None
        others = {k: f[k][()] for k in ("wheels/x", "wheels/penetration",
                                        "wheels/rail_displacement", "modal/zeta",
                                        "vehicle/y", "vehicle/y_dot", "vehicle/y_ddot",
                                        "static/g", "static/q_shift") if k in f}
        return check_mbs_arrays(f["time"][()], f["wheels/contact_force"][()], q,
                                f["modal/q_dot"][()], f["modal/q_ddot"][()],
                                f["modal/omega"][()], float(load or 0.0), psi, others)


def mbs_nbytes(passage) -> int:
    """Predicted size of ``mbs.h5`` (its arrays; the static correction adds six more).
    ``passage``: the multibody result duck-typed (``t``, ``x``, ``contact_force``,
    ``penetration``, ``rail_displacement``, ``q``, ``q_dot``, ``q_ddot``, ``y``, ``y_dot``,
    ``y_ddot``, ``rail_loads``)."""
    arrays = (passage.t, passage.x, passage.contact_force, passage.penetration,
              passage.rail_displacement, passage.q, passage.q_dot, passage.q_ddot, passage.y,
              passage.y_dot, passage.y_ddot, passage.rail_loads)
    extra = (3 * (passage.rail_loads.nbytes + passage.q.nbytes) if passage.rail_loads.size
             else 0)
    return int(sum(a.nbytes for a in arrays) + extra)


@dataclass(frozen=True)
class MbsStatic:
    """The static correction of a passage as ``mbs.h5`` stores it: ``g``, ``g_dot``,
    ``g_ddot`` (nt, n_r), the rail DOF rows of the kept modes ``phi_r`` (n_r, m) (for
    ``q_shift = -(g phi_r^T) / omega^2``), the residual modes' ``residual_omega`` and
    ``residual_vectors``, and the basis they refer to (file name, dataset)."""

    g: tuple[np.ndarray, np.ndarray, np.ndarray]
    phi_r: np.ndarray
    residual_omega: np.ndarray
    residual_vectors: np.ndarray
    basis_file: str
    basis: str = "static/translation"


def fill_mbs(f, passage, *, rail_index, wheel_height: np.ndarray | None, vehicle_type: str,
             omega: np.ndarray, zeta: np.ndarray, static: MbsStatic | None) -> None:
    """Fill an open ``mbs.h5`` (layout in the module notes).

    ``passage``: the multibody result duck-typed (``t``, ``x``, ``contact_force``,
    ``penetration``, ``rail_displacement``, ``y``, ``y_dot``, ``y_ddot``, ``dof_names``,
    ``q``, ``q_dot``, ``q_ddot``); ``wheel_height``: None without a vehicle; ``zeta``: the
    (m,) ratios or the (m, m) coupled damping matrix (stored with its diagonal as ratios).
    """
    f["time"] = passage.t
    w = f.create_group("wheels")
    w["x"] = passage.x
    w["contact_force"] = passage.contact_force
    w["penetration"] = passage.penetration
    w["rail_displacement"] = passage.rail_displacement
    w["rail_index"] = np.asarray(rail_index, dtype=np.int64)
    if wheel_height is not None:
        w["wheel_height"] = wheel_height
    v = f.create_group("vehicle")
    v["y"], v["y_dot"], v["y_ddot"] = passage.y, passage.y_dot, passage.y_ddot
    v.attrs["dof_names"] = json.dumps(list(passage.dof_names))
    v.attrs["type"] = vehicle_type
    mg = f.create_group("modal")
    mg["q"], mg["q_dot"], mg["q_ddot"] = passage.q, passage.q_dot, passage.q_ddot
    if np.ndim(zeta) == 2:                 # coupled modes: the matrix and its diagonal
        mg["damping_matrix"] = zeta
        zeta = np.diag(zeta) / (2.0 * np.where(omega > 0, omega, 1.0))
    mg["omega"], mg["zeta"] = omega, zeta
    if static is not None:
        s = f.create_group("static")
        for suffix, g in zip(("", "_dot", "_ddot"), static.g):
            s["g" + suffix] = g
            s["q_shift" + suffix] = -(g @ static.phi_r.T) / omega**2
        s["residual_omega"] = static.residual_omega
        s["residual_vectors"] = static.residual_vectors
        s.attrs["basis_file"] = static.basis_file
        s.attrs["basis"] = static.basis


def write_mbs_h5(path: Path, passage, *, attrs: Mapping[str, Any],
                 check: Callable[[Path], Sequence[str]] | None = None, **fields) -> str:
    """Write ``mbs.h5`` (serial, rank 0; checked, atomic, recorded); returns its digest.
    ``attrs``: the provenance and stats; ``fields``: those of :func:`fill_mbs`."""
    def fill(f, parallel: bool) -> None:
        fill_mbs(f, passage, **fields)

    return write_h5(path, None, fill, size_hint=mbs_nbytes(passage), attrs=attrs,
                    check=check)


class MbsFileError(UserError):
    """A missing, unreadable, incomplete or inconsistent ``mbs.h5`` (or the
    static-correction basis it names)."""


def _dataset(f, path: Path, name: str):
    if name not in f:
        raise MbsFileError(f"{path}: dataset '{name}' is missing")
    ds = f[name]
    if not hasattr(ds, "shape"):
        raise MbsFileError(f"{path}: '{name}' is a group, expected a dataset")
    return ds


@dataclass
class MbsWindow:
    """The histories of a time window of ``mbs.h5`` (:meth:`MbsFile.window`): ``t``, ``q``,
    ``q_dot``, ``q_ddot`` (full resolution), ``first`` (index of the window's first step),
    ``m`` (modal coordinates), ``static`` (None, or ``(basis_file, basis, g, g_dot,
    g_ddot)`` of the static correction, the basis file resolved), ``k`` (its basis
    size)."""

    t: np.ndarray
    q: np.ndarray
    q_dot: np.ndarray
    q_ddot: np.ndarray
    first: int
    m: int
    static: tuple | None
    k: int


class MbsFile:
    """The one reader of ``mbs.h5`` (rank 0; each method opens the file for itself).

    :meth:`window` validates what it reads (:class:`MbsFileError` naming the file, dataset
    and shape at fault); the other methods read plainly (``OSError``, ``KeyError`` of h5py
    on a broken file)."""

    def __init__(self, path: Path):
        self.path = Path(path)

    def _h5(self):
        import h5py

        return h5py.File(self.path, "r")

    def time_step(self) -> float | None:
        """The stored step (``time[1] - time[0]``); None with fewer than two steps."""
        with self._h5() as f:
            t = f["time"][:2]
        return float(t[1] - t[0]) if t.size == 2 else None

    def has_static_correction(self) -> bool:
        """Whether the file holds the ``/static`` group of the static correction."""
        with self._h5() as f:
            return "static" in f

    def contact(self) -> tuple[np.ndarray, np.ndarray]:
        """``wheels/x`` and ``wheels/contact_force`` (nt, n_wheels)."""
        with self._h5() as f:
            return f["wheels/x"][()], f["wheels/contact_force"][()]

    def modal_accelerations(self) -> tuple[np.ndarray, np.ndarray]:
        """``modal/q_ddot`` (nt, m) and ``modal/omega`` (m,)."""
        with self._h5() as f:
            return f["modal/q_ddot"][()], f["modal/omega"][()]

    def summary(self) -> dict:
        """``n_modes``, ``zeta`` (the modal damping used), ``dt`` (0 with one step) and
        ``inputs_sha256`` (``'?'`` when absent) for the report."""
        with self._h5() as f:
            return {"n_modes": f["modal/omega"].shape[0], "zeta": f["modal/zeta"][()],
                    "dt": (float(f["time"][1] - f["time"][0]) if f["time"].shape[0] > 1
                           else 0.0),
                    "inputs_sha256": f.attrs.get("inputs_sha256", "?")}

    def window(self, n_modes: int, n_nodes: int, window: tuple[float, float] | None = None,
               correction_rates: bool = False, modes_name: str = "the modes file"
               ) -> MbsWindow:
        """Validate the file and read the histories of the time window (serial).

        With a static correction the displacement coordinates are always corrected
        (``q + q_shift`` and the static basis with ``g``); the velocity and acceleration
        coordinates only when ``correction_rates`` (otherwise the modes' own ``q_dot``,
        ``q_ddot``, and ``g_dot = g_ddot = 0``: the classical mode-acceleration method).
        ``n_modes``, ``n_nodes``: of the modes the histories go with (``modes_name`` in the
        messages); the static basis must be (k, n_nodes, 3).
        """
        path = self.path
        with open_input(path, "multibody results file", MbsFileError) as f:
            if int(text_attr(f, "complete", 0)) != 1:
                raise MbsFileError(f"{path} is incomplete (attribute complete != 1); rerun "
                                   "the multibody stage")
            t = _dataset(f, path, "time")[()]
            if t.ndim != 1 or len(t) == 0:
                raise MbsFileError(f"{path}: dataset 'time' has shape {t.shape}, expected "
                                   "(nt,) with nt >= 1")
            if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
                raise MbsFileError(f"{path}: 'time' must be finite and strictly increasing")
            nt = len(t)
            if window is None:
                i0, i1 = 0, nt
            else:
                t0, t1 = (float(v) for v in window)
                if not t0 <= t1:
                    raise MbsFileError(f"time window {window!r}: start must not exceed end")
                i0 = int(np.searchsorted(t, t0, "left"))
                i1 = int(np.searchsorted(t, t1, "right"))
                if i1 <= i0:
                    raise MbsFileError(f"time window {window!r} contains no step of {path} "
                                       f"(time {t[0]} .. {t[-1]} s)")
            names = ("modal/q", "modal/q_dot", "modal/q_ddot")
            hist = _histories(f, path, names, nt, i0, i1)
            m = hist[0].shape[1]
            if not 1 <= m <= n_modes:
                raise MbsFileError(f"{path}: modal/q has {m} modal coordinates but "
                                   f"{modes_name} holds {n_modes} modes (need 1 <= m <= "
                                   f"{n_modes})")
            for name, h in zip(names, hist):
                if not np.all(np.isfinite(h)):
                    raise MbsFileError(f"{path}: dataset '{name}' has non-finite values")
            static, k = None, 0
            if "static" in f:
                static, k = _static(f["static"], path, nt, n_nodes, i0, i1)
                # mode-acceleration: the static basis holds K^-1 g, so the modes' own static
                # part Phi Lambda^-1 Phi_r^T g is removed from the modal coordinates
                shifts = ("q_shift", "q_shift_dot", "q_shift_ddot")
                for j, name in enumerate(shifts if correction_rates else shifts[:1]):
                    if f"static/{name}" in f:
                        hist[j] = hist[j] + f[f"static/{name}"][i0:i1, :m]
                if not correction_rates:
                    file, basis, g, g_dot, g_ddot = static
                    static = (file, basis, g, np.zeros_like(g_dot), np.zeros_like(g_ddot))
        return MbsWindow(t[i0:i1], hist[0], hist[1], hist[2], i0, m, static, k)


def _histories(f, path: Path, names: tuple[str, ...], nt: int, i0: int, i1: int
               ) -> list[np.ndarray]:
    """Rows ``i0:i1`` of the (nt, m) datasets ``names`` (validated: present, 2-D with nt
    rows, the same number of columns)."""
    hist = []
    for name in names:
        ds = _dataset(f, path, name)
        if ds.ndim != 2 or ds.shape[0] != nt:
            raise MbsFileError(f"{path}: dataset '{name}' has shape {ds.shape}, expected "
                               f"(nt, columns) with nt = {nt}")
        hist.append(ds[i0:i1].astype(float))
    if any(h.shape[1] != hist[0].shape[1] for h in hist):
        raise MbsFileError(f"{path}: {', '.join(names)} have different shapes "
                           f"{[h.shape for h in hist]}")
    return hist


def _static(g, path: Path, nt: int, n: int, i0: int, i1: int) -> tuple[tuple, int]:
    """The static-correction basis of the ``/static`` group (validated against its file)."""
    for key in ("basis_file", "basis"):
        if key not in g.attrs:
            raise MbsFileError(f"{path}: group 'static' has no attribute '{key}'")
    basis_file = (path.parent / str(text_attr(g, "basis_file"))).resolve()
    basis = str(text_attr(g, "basis"))
    hist = _histories(g.file, path, ("static/g", "static/g_dot", "static/g_ddot"), nt, i0, i1)
    k = hist[0].shape[1]
    with open_input(basis_file, "static-correction basis file", MbsFileError) as f:
        if "complete" in f.attrs and int(text_attr(f, "complete")) != 1:
            raise MbsFileError(f"{basis_file} is incomplete (attribute complete != 1)")
        ds = _dataset(f, basis_file, basis)
        if ds.shape != (k, n, 3):
            raise MbsFileError(f"{basis_file}: dataset '{basis}' has shape {ds.shape}, "
                               f"expected (k, n, 3) = ({k}, {n}, 3) to match "
                               f"{path}:static/g and the modes")
    return (str(basis_file), basis, *hist), k


def passage_inputs(out_dir: Path) -> tuple[str, ...]:
    """The modal solution's files a reader of the passage in ``out_dir`` rests on, upstream
    first: ``modes.h5``, ``static.h5`` when ``mbs.h5`` holds a static correction, then
    ``mbs.h5`` (the inputs of ``railvib reconstruct``, and of ``railvib assess`` before
    the reconstruction's own files)."""
    names = [MODES_H5, MBS_H5]
    try:
        if MbsFile(Path(out_dir) / MBS_H5).has_static_correction():
            names.insert(1, STATIC_H5)
    except OSError:
        pass
    return tuple(names)
