"""Designs in the unit hypercube, the Gaussian copula, and the samples of the marginals.

Methods (``uncertainty.method``):

* ``mc``: independent uniform points (NumPy's PCG64 generator, seeded);
* ``lhs``: a Latin hypercube (SALib ``sample.latin``): every marginal stratified into
  ``samples`` equal-probability bins;
* ``sobol``: Saltelli's scheme on a scrambled Sobol' sequence (SALib ``sample.sobol``,
  first-order and total indices): ``samples`` base points (a power of 2) give
  ``samples * (d + 2)`` model runs (the matrices A, B and the d mixes A_B^i).

Correlations: a Gaussian copula. The uniform design ``u`` becomes standard normals
``z = Phi^-1(u)``, correlated by the Cholesky factor ``L`` of the correlation matrix
(``y = z L^T``), and back to uniforms ``Phi(y)`` that the marginals' inverse CDFs turn
into values. The matrix is of the normal scores (for Gaussian marginals it is the
correlation of the values; for others Spearman's rank correlation is
``6/pi asin(r/2)``, within 0.02 of r).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

from .distributions import Marginal

METHODS = ("lhs", "mc", "sobol")
#: The design's probabilities are kept this far inside (0, 1) so that the inverse CDFs of
#: unbounded marginals stay finite (a Sobol' point may be exactly 0).
_EDGE = 1e-12


def salib_problem(names: Sequence[str]) -> dict:
    """The SALib problem of ``d`` inputs on the unit hypercube."""
    return {"num_vars": len(names), "names": list(names), "bounds": [[0.0, 1.0]] * len(names)}


def unit_design(method: str, n: int, d: int, seed: int) -> np.ndarray:
    """The design ``(rows, d)`` in ``[0, 1]^d``: ``n`` rows (``mc``, ``lhs``) or
    ``n (d + 2)`` (``sobol``, Saltelli's order: per base point A, A_B^1..A_B^d, B)."""
    if method == "mc":
        u = np.random.default_rng(seed).random((n, d))
    elif method == "lhs":
        from SALib.sample import latin

        u = latin.sample(salib_problem([f"x{i}" for i in range(d)]), n, seed=seed)
    elif method == "sobol":
        from SALib.sample import sobol

        u = sobol.sample(salib_problem([f"x{i}" for i in range(d)]), n,
                         calc_second_order=False, scramble=True, seed=seed)
    else:
        raise ValueError(f"method {method!r}: allowed {METHODS}")
    return np.clip(np.asarray(u, dtype=float), _EDGE, 1.0 - _EDGE)


def correlate(u: np.ndarray, correlation: np.ndarray | None) -> np.ndarray:
    """Uniforms ``u`` with the Gaussian copula of ``correlation`` (None or the identity:
    unchanged)."""
    if correlation is None or np.allclose(correlation, np.eye(u.shape[1])):
        return u
    lower = np.linalg.cholesky(np.asarray(correlation, dtype=float))
    y = stats.norm.ppf(u) @ lower.T
    return np.clip(stats.norm.cdf(y), _EDGE, 1.0 - _EDGE)


def sample_values(marginals: Sequence[Marginal], method: str, n: int, seed: int,
                  correlation: np.ndarray | None = None) -> np.ndarray:
    """Samples ``(rows, d)`` of the marginals (columns in their order).

    Parameters
    ----------
    marginals
        The distributions.
    method, n, seed
        :func:`unit_design`.
    correlation
        ``(d, d)`` correlation of the normal scores (None: independent).
    """
    u = correlate(unit_design(method, n, len(marginals), seed), correlation)
    return np.column_stack([m.ppf(u[:, j]) for j, m in enumerate(marginals)])


def saltelli_base_rows(n_rows: int, d: int) -> np.ndarray:
    """Indices of the A and B rows of a Saltelli design of ``n_rows`` rows (the
    independent draws of the joint distribution: percentiles and exceedances use them)."""
    block = d + 2
    starts = np.arange(0, n_rows - n_rows % block, block)
    return np.sort(np.concatenate([starts, starts + block - 1]))
