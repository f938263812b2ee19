"""The modal damping of the multibody run: the ratios or matrix of the kept and residual modes.

``modal.damping`` chooses the model (``uniform``, ``strain_energy``, ``rayleigh``, ``full``);
the ``mbs.damping_modes`` / ``mbs.damping_ratios`` overrides then set single modes. Used by
the ``mbs`` stage (:mod:`.stage`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..io.files import MODAL_DAMPING_H5, MODES_H5
from ..problem import Problem
from .case_vehicle import MBSInputError

if TYPE_CHECKING:
    from ..config import Case
    from ..io.stage_protocol import StageContext


def modal_damping(case: Case, m: int, modes_path: Path | None = None,
                  ctx: StageContext | None = None) -> np.ndarray:
    """(m,) damping ratios, or the (m, m) modal damping matrix, with the ``mbs.damping_*``
    overrides applied.

    ``modal.damping = 'uniform'``: ``modal.damping_ratio`` for every mode;
    ``'strain_energy'``: per material from the strain energies stored in ``modes_path``
    (:func:`railvib_hpc.modal.energy.damping_from_energies`); ``'rayleigh'``:
    ``alpha / (2 omega) + beta omega / 2`` (:mod:`railvib_hpc.model.damping`); ``'full'``:
    the matrix ``D = Phi^T C Phi`` from ``modal_damping.h5`` next to ``modes_path``
    (:func:`railvib_hpc.modal.projection.compose_damping`), whose diagonal the overrides set
    to ``2 zeta omega``, verified through ``ctx``, the ``mbs`` stage's context
    (:func:`damping_parts`).

    Raises
    ------
    MBSInputError
        ``strain_energy`` damping with a ``modes.h5`` that has no strain energies, ``full``
        damping without a matching ``modal_damping.h5``.
    """
    kind = case["modal.damping"]
    omega = None
    if kind in ("rayleigh", "full"):
        import h5py

        with h5py.File(modes_path, "r") as f:
            omega = np.sqrt(np.maximum(f["modes/eigenvalue"][:m], 0.0))
    if kind == "strain_energy":
        from ..io.formats.modes import read_strain_energies
        from ..modal.energy import damping_from_energies

        energies = read_strain_energies(modes_path) if modes_path is not None else None
        if energies is None:
            raise MBSInputError(f"modal.damping = 'strain_energy': {modes_path} holds no "
                                "per-material strain energies (written by an older version); "
                                "rerun 'railvib modal' to recompute it")
        zeta = damping_from_energies(energies, Problem.from_case(case))[:m].copy()
    elif kind == "rayleigh":
        from ..model.damping import problem_rayleigh, rayleigh_ratio

        zeta = rayleigh_ratio(*problem_rayleigh(Problem.from_case(case)), omega)
    elif kind == "full":
        from ..modal.projection import compose_damping

        d = compose_damping(Problem.from_case(case), damping_parts(ctx, modes_path), omega)
        return _override_diagonal(case, d, omega, m)
    else:
        zeta = np.full(m, case["modal.damping_ratio"])
    for k, r in zip(case["mbs.damping_modes"], case["mbs.damping_ratios"]):
        if int(k) <= m:
            zeta[int(k) - 1] = r
    return zeta


def damping_parts(ctx: StageContext, modes_path: Path) -> dict[str, np.ndarray]:
    """The projected damping parts of ``modal_damping.h5`` next to ``modes_path`` (rank 0).

    Both files are verified for the case through the stage's context, as the ``modal``
    stage's products it needs (:meth:`~railvib_hpc.io.stage_protocol.StageContext.input`),
    as a stage verifies what it reads.

    Raises
    ------
    MBSInputError
        Without a ``modal_damping.h5``.
    StaleInputError
        For a ``modes.h5`` or ``modal_damping.h5`` that is not current for the case or not
        sound.
    ValueError
        Without a context (``ctx`` None): the files would be read unverified.
    """
    from ..io.formats.modal_damping import read_damping_parts

    out_dir = Path(modes_path).parent
    if not (out_dir / MODAL_DAMPING_H5).exists():
        raise MBSInputError(f"modal.damping = 'full' needs {out_dir / MODAL_DAMPING_H5}: "
                            "run 'railvib modal' with modal.damping = 'full' first")
    if ctx is None or ctx.out_dir != out_dir:
        raise ValueError(f"modal.damping = 'full': {out_dir / MODAL_DAMPING_H5} is read "
                         "through the mbs stage's context of its folder (it verifies it)")
    ctx.input("modal", (MODES_H5, MODAL_DAMPING_H5))
    return read_damping_parts(out_dir / MODAL_DAMPING_H5)


def _override_diagonal(case: Case, d: np.ndarray, omega: np.ndarray, m: int) -> np.ndarray:
    """``mbs.damping_modes`` / ``damping_ratios`` on the diagonal of a damping matrix."""
    for k, r in zip(case["mbs.damping_modes"], case["mbs.damping_ratios"]):
        if int(k) <= m:
            d[int(k) - 1, int(k) - 1] = 2.0 * r * omega[int(k) - 1]
    return d


def residual_damping(case: Case, zeta: np.ndarray, res, rest_rows: np.ndarray,
                     omega: np.ndarray, omega_rest: np.ndarray, modes_path: Path,
                     ctx: StageContext | None = None) -> np.ndarray:
    """Damping of the kept modes followed by the residual modes of the static correction.

    ``modal.damping = 'uniform'`` (and ``'strain_energy'``, whose per-material shares the
    residual modes do not have): ``modal.damping_ratio`` for them; ``'rayleigh'``: the
    Rayleigh ratio at their frequencies (exact: ``[Phi, X' V]`` diagonalises K and M);
    ``'full'``: the projected parts of ``[Phi, X']`` in ``modal_damping.h5`` turned onto the
    new basis (:func:`.static_correction.residual_damping_parts`) and composed like the
    modes' (dashpots, pads and materials couple modes and residual modes), verified
    through ``ctx`` (:func:`damping_parts`).
    """
    kind = case["modal.damping"]
    m = omega.size
    if kind == "full":
        from ..modal.projection import compose_damping
        from .static_correction import residual_damping_parts

        try:
            parts = residual_damping_parts(damping_parts(ctx, modes_path), res, rest_rows,
                                           omega_rest, m)
        except ValueError as exc:
            raise MBSInputError(f"{Path(modes_path).with_name(MODAL_DAMPING_H5)}: {exc}; "
                                "rerun 'railvib modal' with mbs.static_correction = true") \
                from exc
        om = np.concatenate([omega, res.omega])
        return _override_diagonal(case, compose_damping(Problem.from_case(case), parts, om),
                                  om, m)
    if kind == "rayleigh":
        from ..model.damping import problem_rayleigh, rayleigh_ratio

        extra = rayleigh_ratio(*problem_rayleigh(Problem.from_case(case)), res.omega)
    else:
        extra = np.full(res.omega.size, case["modal.damping_ratio"])
    return np.concatenate([zeta, extra])
