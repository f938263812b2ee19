"""Eigensolver honesty: residuals above the tolerance are not called converged (issue 16, 3).

Rule (:func:`railvib_hpc.modal.eigen.convergence_verdict`): a mode with relative residual
``rho <= modal.tol`` is converged; ``tol < rho <= floor`` (its round-off floor) and
``rho <= sqrt(tol)`` is accepted with a warning (ill-conditioned model); anything else is an
error naming the count, the worst residual and its mode. The mesh check warns on extreme
aspect ratios and tiny elements.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from modal_cases import column_mesh, soil_case, solve, to_scipy

from railvib_hpc.cli import run
from railvib_hpc.mesh.stage import ASPECT_RATIO_WARNING, quality_warnings
from railvib_hpc.modal import block_lanczos, eigen
from railvib_hpc.modal.eigen import EigenSolveError

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
RULES = {"bottom": ("ux", "uy", "uz")}


def _early_stop(monkeypatch, internal_tol: float) -> None:
    """Make block Lanczos stop at a looser internal tolerance than the one checked."""
    real = block_lanczos.block_lanczos

    def loose(op, nev, r0, **kw):
        kw["tol"] = internal_tol
        return real(op, nev, r0, **kw)

    monkeypatch.setattr(block_lanczos, "block_lanczos", loose)


def test_unconverged_modes_are_an_error_naming_count_and_worst_residual(monkeypatch):
    """Before: the true residuals (up to ~1e-3 here) were printed but the modes were
    accepted as converged."""
    _early_stop(monkeypatch, 1e-1)
    monkeypatch.setattr(eigen, "EXTRA_PURIFICATIONS", 0)
    with pytest.raises(EigenSolveError,
                       match=r"(\d+) of 8 modes did not converge: worst relative residual "
                             r"\S+ \(mode \d+, [\d.]+ Hz\) > modal.tol = 1.0e-10.*stopped "
                             r"early") as err:
        solve(column_mesh(40), soil_case(), RULES, 8)
    assert int(str(err.value).split()[0]) >= 1


def test_extra_purification_brings_the_true_residuals_below_the_tolerance(monkeypatch):
    _early_stop(monkeypatch, 1e-6)
    res, *_ = solve(column_mesh(40), soil_case(), RULES, 8)
    assert res.stats["extra_purifications"] >= 1
    assert np.all(res.residuals <= np.maximum(1e-10, res.residual_floors))


def _column_with_sliver(thickness: float):
    mesh = column_mesh(20)
    z = mesh.points[:, 2]
    levels = np.unique(z)
    z[z > levels[10] + 1e-12] -= (levels[11] - levels[10]) - thickness
    return mesh


def test_round_off_limited_modes_are_a_warning_and_hopeless_ones_an_error():
    # a 0.1 mm layer in a 5.5 m column: residuals ~1e-8 > tol = 1e-10, at the round-off floor
    res, *_ = solve(_column_with_sliver(1e-4), soil_case(), RULES, 6)
    assert res.warnings and "limited by round-off" in res.warnings[0]
    limited = res.residuals > 1e-10
    assert np.all(res.residuals[limited] <= res.residual_floors[limited])
    # a 1e-9 m layer: residuals ~1e-3 > sqrt(tol): not even the frequencies can be trusted
    with pytest.raises(EigenSolveError, match=r"did not converge.*round-off floor.*cause: "
                                              r"round-off: the model is too ill-conditioned"):
        solve(_column_with_sliver(1e-9), soil_case(), RULES, 6)


def test_well_conditioned_model_has_no_warning_and_no_extra_work():
    res, *_ = solve(column_mesh(16), soil_case(), {"bottom": ("ux", "uy", "uz"),
                                                   "all": ("uy", "uz")}, 3)
    assert res.warnings == [] and res.stats["extra_purifications"] == 0
    assert np.all(res.residuals <= 1e-10) and res.stats["max_solve_residual"] < 1e-10


def test_mesh_check_thresholds():
    ok = {"max_aspect_ratio": 6.67, "min_edge": 0.1, "model_size": 50.0}
    assert quality_warnings(ok, 1e-8) == []
    flat = dict(ok, max_aspect_ratio=6e6)
    assert "aspect ratio 6e+06" in quality_warnings(flat, 1e-8)[0]
    assert quality_warnings(dict(ok, max_aspect_ratio=ASPECT_RATIO_WARNING), 1e-8) == []
    # tiny: h < L sqrt(12 u / tol) = 2.6 cm at L = 50 m, tol = 1e-8
    assert quality_warnings(dict(ok, min_edge=0.03), 1e-8) == []
    assert "tiny elements: shortest edge 0.02 m" in quality_warnings(dict(ok, min_edge=0.02),
                                                                      1e-8)[0]


@pytest.mark.slow
def test_sliver_in_the_model_warns_in_mesh_and_modal(tmp_path, capsys):
    """A 1e-7 m slab: the mesh check names the aspect ratio and the tiny elements, the
    modal stage the round-off-limited modes (the run still completes: the eigenvalues are
    accurate to ~residual^2). Before: silent."""
    code = run(["modal", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
                "modal.n_modes=6", "--set", "building.slab_thickness=1e-7", "--out",
                str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    assert "WARNING (mesh check): max aspect ratio" in out
    assert "WARNING (mesh check): tiny elements: shortest edge 1e-07 m" in out
    assert "modes are limited by round-off" in out
    import json

    import h5py

    with h5py.File(tmp_path / "modes.h5", "r") as f:
        stats = json.loads(f.attrs["stats"])
    assert stats["convergence_warnings"]


@pytest.mark.slow
def test_unconverged_stage_exits_2_with_one_line(tmp_path, capsys, monkeypatch):
    _early_stop(monkeypatch, 1e-1)
    monkeypatch.setattr(eigen, "EXTRA_PURIFICATIONS", 0)
    code = run(["modal", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
                "modal.n_modes=6", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert "of 6 modes did not converge: worst relative residual" in err
    assert "Traceback" not in err
    assert not (tmp_path / "modes.h5").exists()


def _rough_ritz_vector(monkeypatch, column: int, size: float) -> None:
    """Add a rough error (a random vector, ``size`` x the largest entry) to one Ritz vector
    block Lanczos returns: its Lanczos estimate says converged, its true residual does not."""
    from mpi4py import MPI

    real = block_lanczos.block_lanczos

    def rough(op, nev, r0, **kw):
        theta, X, st = real(op, nev, r0, **kw)
        scale = op.comm.allreduce(float(np.abs(X[:, column]).max()), op=MPI.MAX)
        noise = block_lanczos.start_block(op.n_global, r0, r0 + op.n_local, 1, seed=99)
        X[:, column] += size * scale * noise[:, 0]
        return theta, X, st

    monkeypatch.setattr(block_lanczos, "block_lanczos", rough)


def _rough_vector_is_caught(monkeypatch, comm=None) -> None:
    """The first Rayleigh-Ritz step accepts a Ritz pair by its true residual only: a pair
    whose vector is rough is purified, the result is the clean run's."""
    rules = {"bottom": ("ux", "uy", "uz"), "all": ("uy", "uz")}
    clean, *_ = solve(column_mesh(16), soil_case(), rules, 3, comm=comm)
    _rough_ritz_vector(monkeypatch, 0, 1e-6)
    res, *_ = solve(column_mesh(16), soil_case(), rules, 3, comm=comm)
    assert res.stats["purified_modes"] > clean.stats["purified_modes"]
    assert np.all(res.residuals <= 1e-10)
    np.testing.assert_allclose(res.eigenvalues, clean.eigenvalues, rtol=1e-10, atol=0)


def test_a_ritz_pair_above_the_tolerance_is_purified_not_accepted(monkeypatch):
    """Before (issue 26), every Ritz vector was purified; now only those whose true residual
    fails after the first Rayleigh-Ritz step: a rough one must be among them."""
    _rough_vector_is_caught(monkeypatch)


@pytest.mark.mpi
def test_a_ritz_pair_above_the_tolerance_is_purified_on_every_rank_count(monkeypatch):
    from mpi4py import MPI

    _rough_vector_is_caught(monkeypatch, MPI.COMM_WORLD)


def test_the_first_rayleigh_ritz_step_is_made_only_where_the_checks_ask(monkeypatch):
    """Issue 26: block Lanczos's Ritz vectors are checked as they are (K and M products,
    Rayleigh quotients, Gram matrices, true residuals); the Rayleigh-Ritz step with K and M
    is made only when their measured Gram errors ask for it. Skipping it, or forcing it,
    gives the same modes to ~residual^2. (An ill-conditioned basis gets it: the 60-element
    column's band of test_bands.py::test_column_bands_equal_single_shift, whose lowest Ritz
    vectors overlap by 4e-10, fails there without it.)"""
    from railvib_hpc.modal import ritz

    rules = {"bottom": ("ux", "uy", "uz"), "all": ("uy", "uz")}
    runs = {}
    for name, gram, spread in (("forced", -1.0, ritz.RAW_RITZ_SPREAD),
                               ("skipped", np.inf, np.inf)):
        monkeypatch.setattr(ritz, "RAW_RITZ_GRAM", gram)
        monkeypatch.setattr(ritz, "RAW_RITZ_SPREAD", spread)
        runs[name], K, M, _ = solve(column_mesh(30), soil_case(), rules, 10)
    forced, skipped = runs["forced"], runs["skipped"]
    assert forced.stats["first_rayleigh_ritz"].startswith("M-Gram error")
    assert skipped.stats["first_rayleigh_ritz"] == "skipped"
    assert skipped.stats["purified_modes"] < 10                    # some pairs kept as they are
    np.testing.assert_allclose(skipped.eigenvalues, forced.eigenvalues, rtol=1e-12, atol=0)
    for res in (forced, skipped):
        assert np.all(res.residuals <= np.maximum(1e-10, res.residual_floors))
        assert res.stats["max_orthonormality_error"] <= 1e-12
        # the checks measured the returned vectors themselves
        Ks, Ms = to_scipy(K), to_scipy(M)
        phi = res.phi
        assert np.abs(phi.T @ (Ms @ phi) - np.eye(10)).max() <= 1e-12
        r = Ks @ phi - (Ms @ phi) * res.eigenvalues
        rho = np.linalg.norm(r, axis=0) / np.linalg.norm(Ks @ phi, axis=0)
        np.testing.assert_allclose(rho, res.residuals, rtol=1e-2, atol=1e-14)
