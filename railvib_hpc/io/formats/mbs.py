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

Writer: the multibody stage (:mod:`railvib_hpc.mbs.stage`). Check: :func:`check_mbs`,
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

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from .checks import CONTACT_FORCE_FACTOR, absent, exceeds, h5_read, nonfinite, static_wheel_load

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
