"""Data checks of the stage files: finite values and plausibility against the model's sizes
and the case's loads, on write and on reuse.

Each ``check_<file>(path, full, context)`` returns a list of problems (empty: sound).
``full`` is False when the file's content digest matches the record written right after
its write-time checks: then only the cheap checks run (attributes, shapes, small
datasets); otherwise the big datasets are streamed too. The same array checks run on
the data in memory before a file is written.

Plausibility bounds (named factors, each with its derivation)
-------------------------------------------------------------
* Mass-normalised modes, ``phi^T M phi = 1``: for a lumped node mass ``m_i`` the
  translation obeys ``m_i |phi_i|^2 <= 1 / c`` where ``c`` is the smallest eigenvalue of
  an element's consistent mass matrix relative to its lumped one: ``1/3`` for linear
  1-D elements, ``1/27`` for the trilinear hexahedron (tensor product). Hence
  ``sqrt(m_i) |phi_i| <= sqrt(27) = 5.2``; :data:`MODE_SHAPE_BOUND` = 6. (The coarse
  thesis model reaches 0.06.)
* Rotations are displacement gradients: ``|theta| <= ROTATION_FACTOR max|u| / h_min``
  with ``h_min`` the shortest line element (:data:`ROTATION_FACTOR` = 100).
* Contact forces: ``|F| <= CONTACT_FORCE_FACTOR`` x the largest static wheel load
  (:data:`CONTACT_FORCE_FACTOR` = 50; wheel-flat impacts reach 3-5 x static).
* Modal coordinates of the passage (Duhamel): with ``psi_i`` the largest modal amplitude
  at the rails (translation plus element length times rotation), ``F`` the sum of the
  peak wheel forces, ``B_i = psi_i F / omega_i^2`` the static modal deflection and
  ``D_i = 1 + omega_i T`` the growth bound over the duration ``T`` (exact for the
  undamped oscillator started at static equilibrium, damping only lowers it):
  ``|q_i| <= K B_i D_i``, ``|q_dot_i| <= K B_i omega_i D_i``,
  ``|q_ddot_i| <= K B_i omega_i^2 (1 + 2 D_i)`` with :data:`MODAL_RESPONSE_FACTOR`
  ``K = 10``.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .files import (
    FIELDS_H5,
    MBS_H5,
    MESH_H5,
    MODAL_DAMPING_H5,
    MODES_H5,
    PROBES_H5,
    STATIC_H5,
    TRANSIENT_CHECKPOINT_H5,
    TRANSIENT_FIELDS,
    TRANSIENT_H5,
    TRANSIENT_PROBES,
)

#: Bound of ``sqrt(m_i) |phi_i|`` for mass-normalised modes (sqrt(27) rounded up).
MODE_SHAPE_BOUND = 6.0
#: Rotations vs displacement gradient ``max|u| / h_min``.
ROTATION_FACTOR = 100.0
#: Contact force vs the largest static wheel load.
CONTACT_FORCE_FACTOR = 50.0
#: Safety factor on the Duhamel bounds of the modal coordinates.
MODAL_RESPONSE_FACTOR = 10.0
#: Modes per block when streaming ``modes/translation``.
_MODES_PER_BLOCK = 8
#: Steps per block when streaming ``fields.h5``.
_STEPS_PER_BLOCK = 16


def nonfinite(name: str, a: np.ndarray) -> list[str]:
    """``["<name> has k non-finite values"]`` or ``[]``."""
    bad = int(a.size - np.count_nonzero(np.isfinite(a)))
    return [f"{name} has {bad} non-finite value{'s' if bad > 1 else ''}"] if bad else []


def exceeds(name: str, a: np.ndarray, bound: np.ndarray | float, what: str) -> list[str]:
    """``["<name> reaches X, above the bound Y (what)"]`` when ``|a| > bound`` somewhere."""
    excess = np.abs(a) - bound
    if a.size == 0 or not np.any(excess > 0):
        return []
    k = np.unravel_index(int(np.argmax(excess)), a.shape)
    b = bound if np.isscalar(bound) else np.broadcast_to(bound, a.shape)[k]
    return [f"{name} reaches {float(np.abs(a[k])):.3g}, above the bound {float(b):.3g} ({what})"]


def _h5(path: Path):
    import h5py

    return h5py.File(path, "r")


def _need(f, names) -> list[str]:
    return [f"dataset '{n}' is missing" for n in names if n not in f]


# ----------------------------------------------------------------------------- mesh.h5
def inverted_hexes(points: np.ndarray, hexes: np.ndarray) -> int:
    """Number of hexahedra (VTK order) with a non-positive corner Jacobian (inverted or
    garbled; a valid mesh has none: the mesh stage refuses inverted elements). Batched over
    the elements (:func:`~railvib_hpc.fem.reference.element_batches`)."""
    from ..fem.reference import element_batches, hex_corner_determinants

    points, hexes = np.asarray(points), np.asarray(hexes)
    bad = 0
    for s in element_batches(len(hexes)):
        det = hex_corner_determinants(points[hexes[s]])
        bad += int(np.count_nonzero(~(det.min(axis=1) > 0)))
    return bad


def check_mesh_arrays(points, hexes, hex_part, lines, line_part, node_sets=None) -> list[str]:
    """Mesh arrays: finite coordinates, connectivity within the nodes, known part ids, no
    inverted hexahedra."""
    from ..schema import PART_ID

    n = len(points)
    out = nonfinite("mesh/points", np.asarray(points))
    if np.ndim(points) != 2 or np.shape(points)[1:] != (3,):
        out.append(f"mesh/points has shape {np.shape(points)}, expected (n, 3)")
    for name, conn, width in (("mesh/hexes", hexes, 8), ("mesh/lines", lines, 2)):
        conn = np.asarray(conn)
        if conn.ndim != 2 or conn.shape[1] != width:
            out.append(f"{name} has shape {conn.shape}, expected (k, {width})")
        elif conn.size and (conn.min() < 0 or conn.max() >= n):
            out.append(f"{name} refers to nodes outside 0..{n - 1}")
    ids = set(PART_ID.values())
    for name, part, conn in (("mesh/hex_part", hex_part, hexes), ("mesh/line_part", line_part,
                                                                   lines)):
        part = np.asarray(part)
        if part.shape != (len(conn),):
            out.append(f"{name} has shape {part.shape}, expected ({len(conn)},)")
        elif part.size and not set(np.unique(part).tolist()) <= ids:
            out.append(f"{name} has unknown part ids")
    for name, nodes in (node_sets or {}).items():
        nodes = np.asarray(nodes)
        if nodes.size and (nodes.min() < 0 or nodes.max() >= n):
            out.append(f"mesh/node_sets/{name} refers to nodes outside 0..{n - 1}")
    if not out:
        bad = inverted_hexes(points, hexes)
        if bad:
            out.append(f"mesh/hexes has {bad} inverted or degenerate hexahedra")
    return out


def check_mesh(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
               ) -> list[str]:
    """``mesh.h5`` (small: always read completely)."""
    with _h5(path) as f:
        missing = _need(f, ("mesh/points", "mesh/hexes", "mesh/hex_part", "mesh/lines",
                            "mesh/line_part", "mesh/probes/coords"))
        if missing:
            return missing
        g = f["mesh"]
        sets = {k: v[()] for k, v in g["node_sets"].items()} if "node_sets" in g else {}
        return check_mesh_arrays(g["points"][()], g["hexes"][()], g["hex_part"][()],
                                 g["lines"][()], g["line_part"][()], sets) \
            + nonfinite("mesh/probes/coords", g["probes/coords"][()])


# ----------------------------------------------------------------------------- modes.h5
def check_eigenvalues(eigenvalues: np.ndarray) -> list[str]:
    """Finite, positive, ascending (to round-off) eigenvalues."""
    lam = np.asarray(eigenvalues, dtype=float)
    out = nonfinite("modes/eigenvalue", lam)
    if out:
        return out
    if lam.size == 0:
        return ["modes/eigenvalue is empty"]
    if np.any(lam <= 0):
        out.append(f"modes/eigenvalue has {int(np.sum(lam <= 0))} values <= 0 (the model "
                   "must be supported: no rigid-body modes)")
    if np.any(np.diff(lam) < -1e-8 * np.abs(lam[1:])):
        out.append("modes/eigenvalue is not ascending")
    return out


def mode_bounds(nodal_mass: np.ndarray) -> np.ndarray:
    """Bound of ``|phi_i|`` per node from the mass normalisation (module notes)."""
    m = np.asarray(nodal_mass, dtype=float)
    floor = float(m[m > 0].min()) if np.any(m > 0) else 1.0
    return MODE_SHAPE_BOUND / np.sqrt(np.where(m > 0, m, floor))


def check_mode_shapes(translation: np.ndarray, nodal_mass: np.ndarray, first: int = 0
                      ) -> list[str]:
    """Finite, mass-normalisation-bounded translations (m, n, 3) of modes ``first..``."""
    out = nonfinite(f"modes/translation (modes {first + 1}..)", translation)
    if out:
        return out
    mag = np.linalg.norm(translation, axis=2)
    return exceeds(f"modes/translation (modes {first + 1}..)", mag,
                   mode_bounds(nodal_mass)[None, :], "mass normalisation")


def check_modes(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                ) -> list[str]:
    """``modes.h5``: eigenvalues, shapes, masses; with ``full`` every mode shape."""
    with _h5(path) as f:
        missing = _need(f, ("modes/eigenvalue", "modes/frequency_hz", "modes/translation",
                            "modes/rotation", "mesh/points", "mesh/nodal_mass",
                            "mesh/rail_nodes", "mesh/rotation_nodes", "dofs/index"))
        if missing:
            return missing
        lam = f["modes/eigenvalue"][()]
        out = check_eigenvalues(lam)
        n = f["mesh/points"].shape[0]
        tr, rot = f["modes/translation"], f["modes/rotation"]
        nr = f["mesh/rotation_nodes"].shape[0]
        if tr.shape != (len(lam), n, 3):
            out.append(f"modes/translation has shape {tr.shape}, expected ({len(lam)}, {n}, 3)")
        if rot.shape != (len(lam), nr, 3):
            out.append(f"modes/rotation has shape {rot.shape}, expected ({len(lam)}, {nr}, 3)")
        mass = f["mesh/nodal_mass"][()]
        out += nonfinite("mesh/nodal_mass", mass)
        if mass.shape != (n,) or np.any(mass < 0):
            out.append("mesh/nodal_mass must be (n,) and >= 0")
        freq = f["modes/frequency_hz"][()]
        if freq.shape == lam.shape and not out and not np.allclose(
                freq, np.sqrt(np.maximum(lam, 0)) / (2 * np.pi), rtol=1e-9):
            out.append("modes/frequency_hz does not match modes/eigenvalue")
        if out or not full:
            return out
        h_min = _shortest_line(f)
        umax = 0.0
        for k in range(0, len(lam), _MODES_PER_BLOCK):
            block = tr[k:k + _MODES_PER_BLOCK]
            out += check_mode_shapes(block, mass, k)
            if out:
                return out
            umax = max(umax, float(np.abs(block).max()) if block.size else 0.0)
        r = rot[()]
        out += nonfinite("modes/rotation", r)
        if not out and h_min > 0:
            out += exceeds("modes/rotation", r, ROTATION_FACTOR * umax / h_min,
                           "displacement gradient")
    return out


def _shortest_line(f) -> float:
    if "mesh/lines" not in f or f["mesh/lines"].shape[0] == 0:
        return 0.0
    pts, lines = f["mesh/points"][()], f["mesh/lines"][()]
    length = np.linalg.norm(pts[lines[:, 1]] - pts[lines[:, 0]], axis=1)
    length = length[length > 0]
    return float(length.min()) if length.size else 0.0


# ----------------------------------------------------------------------------- static.h5
def check_static(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``static.h5``: finite, symmetric rail flexibility with a non-negative diagonal, and
    the static fields' mass matrix."""
    with _h5(path) as f:
        missing = _need(f, ("static/rail_flexibility", "static/translation",
                            "static/load_dofs", "static/residual_mass"))
        if missing:
            return missing
        x = f["static/rail_flexibility"][()]
        out = nonfinite("static/rail_flexibility", x)
        if not out and (x.ndim != 2 or x.shape[0] != x.shape[1] or np.any(np.diag(x) < 0)
                        or not np.allclose(x, x.T, rtol=1e-8,
                                           atol=1e-12 * float(np.abs(x).max() or 1))):
            out.append("static/rail_flexibility is not a symmetric flexibility matrix")
        mass = f["static/residual_mass"][()]
        if not out:
            out += nonfinite("static/residual_mass", mass)
        if not out and (mass.shape != x.shape or np.any(np.diag(mass) < 0)):
            out.append("static/residual_mass is not a mass matrix of the rail DOFs' static "
                       "fields")
        if full and not out:
            t = f["static/translation"]
            for k in range(0, t.shape[0], 64):
                out += nonfinite("static/translation", t[k:k + 64])
                if out:
                    break
    return out


def check_modal_damping(path: Path, full: bool = True,
                        context: Mapping[str, Any] | None = None) -> list[str]:
    """``modal_damping.h5``: the dashpot and pad parts, every part square, symmetric and
    finite, all of one size."""
    with _h5(path) as f:
        missing = _need(f, ("dashpots", "pads"))
        if missing:
            return missing
        parts: dict = {}
        f.visititems(lambda name, obj: parts.__setitem__(name, obj)
                     if hasattr(obj, "shape") else None)
        size = f["dashpots"].shape
        out: list[str] = []
        for name, d in parts.items():
            if d.ndim != 2 or d.shape[0] != d.shape[1] or d.shape != size:
                out.append(f"{name} has shape {d.shape}, the dashpots {size}")
                break
            if full:
                a = d[()]
                out += nonfinite(name, a)
                if not out and not np.allclose(a, a.T, rtol=1e-8,
                                               atol=1e-12 * float(np.abs(a).max() or 1)):
                    out.append(f"{name} is not symmetric")
                if out:
                    break
    return out


# ----------------------------------------------------------------------------- mbs.h5
def rail_amplitude(modes_path: Path, m: int) -> np.ndarray:
    """(m,) largest modal amplitude at the rails: translation plus element length times
    rotation (what a wheel force can excite; module notes)."""
    with _h5(modes_path) as f:
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
    with _h5(path) as f:
        missing = _need(f, ("time", "wheels/x", "wheels/contact_force", "modal/q",
                            "modal/q_dot", "modal/q_ddot", "modal/omega", "modal/zeta"))
        if missing:
            return missing
        load = _static_wheel_load(f, context)
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


# ----------------------------------------------------------------------------- fields.h5
def check_fields(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``fields.h5``: shapes and times; with ``full`` every field value is finite."""
    names = ("fields/displacement", "fields/velocity", "fields/acceleration")
    with _h5(path) as f:
        missing = _need(f, ("time", "steps", *names, "mesh/points", "mesh/hexes"))
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


# ----------------------------------------------------------------------------- probes.h5
def check_probes(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                 ) -> list[str]:
    """``probes.h5`` (small: always completely): every history finite."""
    with _h5(path) as f:
        missing = _need(f, ("names", "coords", "probes"))
        if missing:
            return missing
        out = []
        for name, g in f["probes"].items():
            for key in ("time", "displacement", "velocity", "acceleration"):
                if key not in g:
                    out.append(f"probes/{name}/{key} is missing")
                else:
                    out += nonfinite(f"probes/{name}/{key}", g[key][()])
        if "rail" in f:
            for key, ds in f["rail"].items():
                out += nonfinite(f"rail/{key}", ds[()])
        return out


# ----------------------------------------------------------------------------- transient.h5
def check_transient(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                    ) -> list[str]:
    """``transient.h5`` (small: always completely): every history finite, consistent shapes,
    time strictly increasing, contact forces within :data:`CONTACT_FORCE_FACTOR` x the
    static wheel load (``context["static_wheel_load"]``, else the stored ``stats``)."""
    context = context or {}
    with _h5(path) as f:
        missing = _need(f, ("time", "wheels/x", "wheels/contact_force", "wheels/penetration",
                            "wheels/rail_displacement", "vehicle/y", "rail/x", "rail/uz",
                            "rail/ry"))
        if missing:
            return missing
        t = f["time"][()]
        out = nonfinite("time", t)
        if not out and (t.ndim != 1 or t.size == 0 or np.any(np.diff(t) <= 0)):
            out.append("time must be non-empty and strictly increasing")
        for name in ("wheels/x", "wheels/contact_force", "wheels/penetration",
                     "wheels/rail_displacement", "wheels/wheel_height", "vehicle/y",
                     "vehicle/y_dot", "vehicle/y_ddot", "rail/uz", "rail/ry"):
            if name not in f:
                continue
            a = f[name][()]
            if a.shape[:1] != t.shape:
                out.append(f"{name} has shape {a.shape}, expected {t.size} rows (time)")
            out += nonfinite(name, a)
        if out:
            return out
        load = _static_wheel_load(f, context)
        if load:
            out += exceeds("wheels/contact_force", f["wheels/contact_force"][()],
                           CONTACT_FORCE_FACTOR * float(load),
                           f"{CONTACT_FORCE_FACTOR:g} x the static wheel load {load:.4g} N")
    return out


def check_checkpoint(path: Path, full: bool = True, context: Mapping[str, Any] | None = None
                     ) -> list[str]:
    """``transient_checkpoint.h5``: the state vectors (one length, finite), the step and the
    recorded histories (finite, at least ``step + 1`` rows)."""
    with _h5(path) as f:
        missing = _need(f, ("state/u", "state/v", "state/a", "small", "history"))
        if missing:
            return missing
        out = []
        step, written = int(f.attrs.get("step", -1)), int(f.attrs.get("fields_written", -1))
        if step < 0 or written < 0:
            out.append(f"its step {step} or fields_written {written} is negative or missing")
        n = f["state/u"].shape
        for name in ("state/u", "state/v", "state/a"):
            if f[name].shape != n:
                out.append(f"{name} has shape {f[name].shape}, expected {n}")
            else:
                out += nonfinite(name, f[name][()])
        for name, ds in (*f["small"].items(), *f["history"].items()):
            out += nonfinite(name, ds[()])
        for name, ds in f["history"].items():
            if ds.ndim == 0 or ds.shape[0] <= step:
                out.append(f"history/{name} has {ds.shape[0] if ds.ndim else 0} rows, the "
                           f"checkpoint is at step {step}")
        return out


#: The data check of each stage file (by table name).
CHECKS = {MESH_H5: check_mesh, MODES_H5: check_modes, STATIC_H5: check_static,
          MODAL_DAMPING_H5: check_modal_damping, MBS_H5: check_mbs,
          FIELDS_H5: check_fields, PROBES_H5: check_probes,
          TRANSIENT_H5: check_transient, TRANSIENT_FIELDS: check_fields,
          TRANSIENT_PROBES: check_probes, TRANSIENT_CHECKPOINT_H5: check_checkpoint}


def _static_wheel_load(f, context: dict) -> float:
    """The static wheel load [N]: from the caller's context, else from the file's ``stats``
    attribute (0 when neither has it)."""
    load = context.get("static_wheel_load")
    if load is not None:
        return load
    try:
        return max(json.loads(f.attrs.get("stats", "{}")).get("static_wheel_load") or [0.0])
    except (ValueError, TypeError):
        return 0.0
