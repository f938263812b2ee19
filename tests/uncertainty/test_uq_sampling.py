"""Sampling and statistics against exact answers: a 1-D column with a lognormal stiffness,
the Ishigami function's Sobol' indices, the Gaussian copula, the Wilson interval."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from railvib_hpc.uncertainty.distributions import Marginal
from railvib_hpc.uncertainty.sampling import (
    correlate,
    saltelli_base_rows,
    sample_values,
    unit_design,
)
from railvib_hpc.uncertainty.statistics import (
    convergence,
    exceedance,
    percentiles,
    sobol_indices,
    wilson,
)

#: A 1-D shear column of 20 elements, fixed at the base (the lowest mode of a fixed-free
#: bar: f1 -> c / (4 H) as the mesh is refined).
N_ELEMENTS, MASS, STIFFNESS = 20, 50.0, 2.0e6


def column_frequencies(k: np.ndarray) -> np.ndarray:
    """Lowest natural frequency [Hz] of the column for each element stiffness ``k``
    (batched: one stiffness matrix per sample)."""
    n = N_ELEMENTS
    unit = np.zeros((n, n))
    i = np.arange(n)
    unit[i, i] = 2.0
    unit[i[:-1], i[:-1] + 1] = unit[i[:-1] + 1, i[:-1]] = -1.0
    unit[-1, -1] = 1.0                                  # free top
    lam = np.linalg.eigvalsh(k[:, None, None] * unit[None] / MASS)[:, 0]
    return np.sqrt(lam) / (2 * np.pi)


@pytest.mark.parametrize("method", ["lhs", "mc"])
def test_column_frequency_is_the_exact_transformed_lognormal(method):
    # k lognormal (mean, cov) => f = f(k0) sqrt(k / k0) lognormal with half the log-sigma
    cov = 0.3
    m = Marginal("k", "k", "lognormal", {"mean": STIFFNESS, "std": cov * STIFFNESS})
    k = sample_values([m], method, 400, seed=7)[:, 0]
    f = column_frequencies(k)
    f_nominal = column_frequencies(np.array([STIFFNESS]))[0]
    s_ln = np.sqrt(np.log1p(cov**2))
    exact = stats.lognorm(s=s_ln / 2, scale=f_nominal * np.exp(-s_ln**2 / 4))
    assert stats.kstest(f, exact.cdf).pvalue > 0.01
    # quantiles within their sampling error (3 standard errors of a sample quantile)
    for q in (0.05, 0.5, 0.95):
        se = np.sqrt(q * (1 - q) / len(f)) / exact.pdf(exact.ppf(q))
        assert abs(np.quantile(f, q) - exact.ppf(q)) < 3 * se
    # the static response u = F / k: lognormal too
    u = 1e3 / k
    exact_u = stats.lognorm(s=s_ln, scale=1e3 / STIFFNESS * np.exp(s_ln**2 / 2))
    assert stats.kstest(u, exact_u.cdf).pvalue > 0.01


def test_ishigami_sobol_indices_match_the_exact_values():
    a, b = 7.0, 0.1
    u = unit_design("sobol", 2048, 3, seed=1)
    x = -np.pi + 2 * np.pi * u
    y = np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])
    # exact (Ishigami & Homma 1990; Sobol' & Levitan 1999)
    v1 = 0.5 * (1 + b * np.pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * np.pi**8 * (1 / 18 - 1 / 50)
    var = v1 + v2 + v13
    exact = {"x1": (v1 / var, (v1 + v13) / var), "x2": (v2 / var, v2 / var),
             "x3": (0.0, v13 / var)}
    got = sobol_indices(["x1", "x2", "x3"], y)
    for name, (s1, st) in exact.items():
        assert got[name]["S1"] == pytest.approx(s1, abs=0.03)
        assert got[name]["ST"] == pytest.approx(st, abs=0.03)
    assert len(saltelli_base_rows(len(y), 3)) == 2 * 2048


def test_gaussian_copula_gives_the_correlation_and_keeps_the_marginals():
    corr = np.array([[1.0, 0.6], [0.6, 1.0]])
    marg = [Marginal("a", "a", "normal", {"mean": 10.0, "std": 2.0}),
            Marginal("b", "b", "uniform", {"low": 0.0, "high": 1.0})]
    x = sample_values(marg, "lhs", 4000, seed=3, correlation=corr)
    z = stats.norm.ppf(np.column_stack([stats.norm.cdf(x[:, 0], 10, 2), x[:, 1]]))
    assert np.corrcoef(z.T)[0, 1] == pytest.approx(0.6, abs=0.03)
    assert stats.kstest(x[:, 1], "uniform").pvalue > 0.01
    assert stats.kstest(x[:, 0], stats.norm(10, 2).cdf).pvalue > 0.01
    u = unit_design("mc", 10, 2, seed=0)
    assert correlate(u, np.eye(2)) is u


def test_wilson_interval_and_exceedance():
    # Wilson (1927) at 95 %: 0 of 10 -> [0, 0.2775]; 5 of 10 -> [0.2366, 0.7634]
    w = wilson(0, 10)
    assert (w["p"], w["low"]) == (0.0, 0.0) and w["high"] == pytest.approx(0.2775, abs=1e-4)
    w = wilson(5, 10)
    assert (w["low"], w["high"]) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    e = exceedance([0.5, 1.5, np.nan, 2.0], 1.0)
    assert (e["k"], e["n"]) == (2, 3)


def test_percentile_intervals_cover_the_true_percentile():
    rng = np.random.default_rng(0)
    hits = 0
    for _ in range(40):
        p = percentiles(rng.normal(size=200))
        assert p["P5"]["low"] <= p["P5"]["value"] <= p["P5"]["high"]
        hits += p["P95"]["low"] <= stats.norm.ppf(0.95) <= p["P95"]["high"]
    assert hits >= 32                          # nominal 95 %: at least 80 % of 40 runs
    conv = convergence(rng.normal(size=50), 1.0)
    assert [c["n"] for c in conv] == [4, 8, 16, 32, 50]
    assert conv[-1]["exceedance"]["n"] == 50
