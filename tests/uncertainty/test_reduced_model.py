"""The parametric reduced model's dense algebra (railvib_hpc.uncertainty.reduced) on a
spring-mass chain, and the study's helpers (reference draw, varied parts, bad input)."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from railvib_hpc.uncertainty.reduced import (
    orthonormalising_map,
    reduced_eigenpairs,
    reduced_matrices,
    relative_residuals,
)


def _chain(n: int = 40):
    """A fixed-free chain of n springs in two parts (lower / upper half): K_g, M_g."""
    k_parts, m_parts = np.zeros((2, n, n)), np.zeros((2, n, n))
    for e in range(n):
        g = 0 if e < n // 2 else 1
        i = [e - 1, e] if e > 0 else [e]
        ke = np.array([[1.0, -1.0], [-1.0, 1.0]]) if e > 0 else np.array([[1.0]])
        k_parts[g][np.ix_(i, i)] += ke
        m_parts[g][e, e] += 1.0
    return k_parts, m_parts


def _basis(k_parts, m_parts, n_modes: int):
    """Nominal modes + static sensitivity vectors K0^-1 K_g Phi, M0-orthonormalised."""
    k0, m0 = k_parts.sum(0), m_parts.sum(0)
    _, phi = scipy.linalg.eigh(k0, m0, subset_by_index=[0, n_modes - 1])
    extra = [np.linalg.solve(k0, kg @ phi) for kg in k_parts]
    v = np.hstack([phi, *extra])
    return v @ orthonormalising_map(v.T @ m0 @ v)


def test_orthonormalising_map_drops_dependent_directions():
    rng = np.random.default_rng(1)
    a = rng.standard_normal((30, 4))
    v = np.hstack([a, a[:, :2] * 3.0])              # two exact dependences
    m = np.diag(rng.uniform(1.0, 2.0, 30))
    c = orthonormalising_map(v.T @ m @ v)
    assert c.shape == (6, 4)
    assert np.allclose((v @ c).T @ m @ (v @ c), np.eye(4), atol=1e-10)


def test_reduced_model_matches_the_full_chain_and_its_residual():
    k_parts, m_parts = _chain()
    v = _basis(k_parts, m_parts, 6)
    kp = np.einsum("ia,gij,jb->gab", v, k_parts, v)
    mp = np.einsum("ia,gij,jb->gab", v, m_parts, v)
    s, t = np.array([0.6, 1.3]), np.array([1.0, 1.2])     # softer base, heavier top
    kr, mr = reduced_matrices(np.zeros_like(kp[0]), np.zeros_like(mp[0]), kp, mp, s, t)
    lam, y = reduced_eigenpairs(kr, mr, 4)
    k = np.tensordot(s, k_parts, 1)
    m = np.tensordot(t, m_parts, 1)
    exact = scipy.linalg.eigh(k, m, eigvals_only=True, subset_by_index=[0, 3])
    phi = v @ y
    kphi, mphi = k @ phi, m @ phi
    res = relative_residuals(((kphi - lam * mphi)**2).sum(0), (kphi**2).sum(0))
    direct = np.linalg.norm(kphi - lam * mphi, axis=0) / np.linalg.norm(kphi, axis=0)
    assert np.allclose(res, direct, rtol=1e-6, atol=1e-12)
    err = np.abs(np.sqrt(lam / exact) - 1.0)
    # a Ritz value is an upper bound; its error is second order in the residual
    assert np.all(lam >= exact * (1 - 1e-12))
    assert np.all(err <= np.maximum(res, 1e-12))
    assert err.max() < 1e-3
    # the modes alone (no sensitivity vectors) are worse: the vectors do their work
    _, phi0 = scipy.linalg.eigh(k_parts.sum(0), m_parts.sum(0), subset_by_index=[0, 9])
    l0 = scipy.linalg.eigh(phi0.T @ k @ phi0, phi0.T @ m @ phi0, eigvals_only=True)[:4]
    assert err.max() < 0.1 * np.abs(np.sqrt(l0 / exact) - 1.0).max()


def test_reduced_eigenpairs_refuses_too_small_a_basis():
    with pytest.raises(ValueError, match="fewer than the 3 modes"):
        reduced_eigenpairs(np.eye(2), np.eye(2), 3)


def test_reference_samples_and_varied_parts():
    from railvib_hpc.config import build_case
    from railvib_hpc.studies.uncertainty import reference_samples, varied_parts

    a = reference_samples(28, 3, 2026)
    assert a == reference_samples(28, 3, 2026) and len(set(a)) == 3 and max(a) < 28
    assert reference_samples(2, 5, 1) == [0, 1]
    case = build_case({}, [
        'soil.layers=[{thickness = 1.5, c_s = 150.0, nu = 0.3, rho = 1800.0}, '
        '{thickness = 0.0, c_s = 250.0, nu = 0.3, rho = 1900.0}]',
        'uncertainty.parameter=[{key="soil.layers[1].c_s", distribution="lognormal", '
        'cov=0.2}, {key="pads.kz", distribution="lognormal", cov=0.2}, '
        '{key="soil.layers[2].rho", distribution="lognormal", cov=0.1}, '
        '{key="vehicle.speed", distribution="uniform", low=20.0, high=30.0}]'])
    assert varied_parts(case) == {"pad_z": ("K",), "soil_layer_1": ("K",),
                                  "soil_layer_2": ("K", "M")}


@pytest.mark.parametrize("more, expect", [
    (["--set", 'uncertainty.model="fast"'], "uncertainty.model"),
    (["--set", 'uncertainty.model="reduced"', "--set", 'uncertainty.parameter=[{key='
      '"soil.layers[1].thickness", distribution="uniform", low=1.0, high=2.0}]'],
     "changes the mesh"),
    (["--set", 'uncertainty.model="reduced"', "--set", 'uncertainty.parameter=[{key='
      '"pads.kz", distribution="lognormal", cov=0.2}]', "--study-set", "solver=direct"],
     "reduces the modal solve"),
])
def test_bad_reduced_input_is_one_line_with_exit_code_2(tmp_path, capsys, more, expect):
    from railvib_hpc.cli import run

    layers = ('soil.layers=[{thickness = 1.5, c_s = 150.0, nu = 0.3, rho = 1800.0}, '
              '{thickness = 0.0, c_s = 250.0, nu = 0.3, rho = 1900.0}]')
    assert run(["study", "uncertainty", "jobs/thesis_baseline.toml", "--list", "--out",
                str(tmp_path), "--set", layers, *more]) == 2
    err = capsys.readouterr()
    lines = [x for x in (err.out + err.err).splitlines() if expect in x]
    assert len(lines) == 1 and "Traceback" not in err.err
