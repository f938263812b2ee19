"""Estimates from the samples and their confidence intervals.

* Percentiles (P5, P50, P95): the sample percentiles (linear interpolation), with a
  percentile-bootstrap interval (``n_boot`` resamples, seeded);
* exceedance probability ``P(value > limit)``: ``k`` of ``n`` samples, with the Wilson
  score interval (Wilson 1927; it stays inside [0, 1] and is not degenerate at k = 0);
* Sobol' indices: first-order ``S1`` and total ``ST`` (SALib ``analyze.sobol``, Saltelli
  2010 / Jansen estimators) with their bootstrap intervals, and whether they are estimates
  at all (:func:`sobol_doubts`: enough base points, every index in [0, 1] within its
  interval);
* convergence: the estimates from the first ``n`` samples, for growing ``n``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy import stats

from .sampling import salib_problem

#: The percentiles of the report.
PERCENTILES = (5.0, 50.0, 95.0)
#: Bootstrap resamples of the percentile intervals (the interval ends move by a few
#: per cent of their width between seeds at 500).
N_BOOTSTRAP = 500


def percentiles(values: Sequence[float], confidence: float = 0.95,
                q: Sequence[float] = PERCENTILES, n_boot: int = N_BOOTSTRAP,
                seed: int = 0) -> dict[str, dict[str, float]]:
    """Percentiles of ``values`` and their bootstrap intervals.

    Returns
    -------
    dict
        ``{"P5": {"value", "low", "high"}, ...}`` (NaN values are ignored; all NaN with
        fewer than 2 finite values).
    """
    y = np.asarray(values, dtype=float)
    y = y[np.isfinite(y)]
    out = {}
    if y.size < 2:
        return {f"P{p:g}": {"value": float("nan"), "low": float("nan"),
                            "high": float("nan")} for p in q}
    est = np.percentile(y, q)
    rng = np.random.default_rng(seed)
    boot = np.percentile(y[rng.integers(0, y.size, (n_boot, y.size))], q, axis=1)
    alpha = (1.0 - confidence) / 2.0
    lo, hi = np.quantile(boot, [alpha, 1.0 - alpha], axis=1)
    for k, p in enumerate(q):
        out[f"P{p:g}"] = {"value": float(est[k]), "low": float(lo[k]), "high": float(hi[k])}
    return out


def wilson(k: int, n: int, confidence: float = 0.95) -> dict[str, float]:
    """The probability ``k / n`` with its Wilson score interval.

    Returns
    -------
    dict
        ``{"p", "low", "high", "k", "n"}`` (NaN for n = 0).
    """
    if n <= 0:
        return {"p": float("nan"), "low": float("nan"), "high": float("nan"), "k": k, "n": n}
    z = float(stats.norm.ppf(0.5 + confidence / 2.0))
    p = k / n
    den = 1.0 + z * z / n
    mid = (p + z * z / (2 * n)) / den
    half = z / den * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    low = 0.0 if k == 0 else max(0.0, mid - half)        # exact ends, not round-off
    high = 1.0 if k == n else min(1.0, mid + half)
    return {"p": p, "low": low, "high": high, "k": k, "n": n}


def exceedance(values: Sequence[float], limit: float, confidence: float = 0.95
               ) -> dict[str, float]:
    """``P(value > limit)`` over the finite values, with its Wilson interval."""
    y = np.asarray(values, dtype=float)
    y = y[np.isfinite(y)]
    return wilson(int((y > limit).sum()), int(y.size), confidence)


def sobol_indices(names: Sequence[str], y: Sequence[float], confidence: float = 0.95,
                  seed: int = 0) -> dict[str, dict[str, float]]:
    """First-order and total Sobol' indices of the outputs ``y`` of a Saltelli design
    (:func:`~.sampling.unit_design` ``sobol``, rows in its order).

    Returns
    -------
    dict
        ``{name: {"S1", "S1_conf", "ST", "ST_conf"}}`` (``*_conf``: half-width of the
        bootstrap interval at ``confidence``).
    """
    from SALib.analyze import sobol

    y = np.asarray(y, dtype=float)
    res = sobol.analyze(salib_problem(names), y, calc_second_order=False,
                        conf_level=confidence, seed=seed)
    return {n: {"S1": float(res["S1"][i]), "S1_conf": float(res["S1_conf"][i]),
                "ST": float(res["ST"][i]), "ST_conf": float(res["ST_conf"][i])}
            for i, n in enumerate(names)}


#: Fewest base points N of a Saltelli design whose Sobol' indices the report shows. Saltelli
#: et al. (2010, Comput. Phys. Commun. 181, 259-270) study their estimators for N of 10^2 to
#: 10^4 and SALib's examples use N = 1024; below, the indices and their bootstrap intervals
#: are not estimates. Measured (bench/sobol_sample_size.py, 20 seeds, S1 and ST of all
#: inputs): the RMS error on the Ishigami function (a = 7, b = 0.1) is 0.39 at N = 4,
#: 0.22 at 16, 0.14 at 32, 0.078 at 64 and 0.042 at 256; on a linear function of three
#: inputs 0.37, 0.14, 0.027, 0.014, 0.001. 64 is the first N with an RMS error below 0.1 on
#: both, enough to rank inputs whose indices differ by more than that.
MIN_SOBOL_BASE_SAMPLES = 64


def sobol_doubts(indices: dict[str, dict[str, float]], n_base: int) -> list[str]:
    """Why the Sobol' indices of one output are not reported as estimates (empty: they are).

    The rule: the design has at least :data:`MIN_SOBOL_BASE_SAMPLES` base points, and every
    index lies in [0, 1] within its interval (``S - conf <= 1`` and ``S + conf >= 0``; a
    true index is in [0, 1], an estimate outside by more than its own interval has not
    converged, and its interval is no interval). A NaN index or interval fails too.

    Parameters
    ----------
    indices
        :func:`sobol_indices`'s result.
    n_base
        The design's base points N (``uncertainty.samples``).

    Examples
    --------
    >>> print(*sobol_doubts({"speed": {"S1": 1.411, "S1_conf": 0.21, "ST": 0.9,
    ...                                "ST_conf": 0.1}}, 64))
    speed S1 = 1.411 ± 0.210 lies outside [0, 1] by more than its interval
    >>> print(*sobol_doubts({"speed": {"S1": 0.5, "S1_conf": 0.1, "ST": 0.6,
    ...                                "ST_conf": 0.1}}, 2))
    the design has N = 2 base points, fewer than 64 (uncertainty.samples)
    """
    out = []
    if n_base < MIN_SOBOL_BASE_SAMPLES:
        out.append(f"the design has N = {n_base} base points, fewer than "
                   f"{MIN_SOBOL_BASE_SAMPLES} (uncertainty.samples)")
    for name, e in indices.items():
        for q in ("S1", "ST"):
            v, c = e[q], e[f"{q}_conf"]
            if not (np.isfinite(v) and np.isfinite(c)) or v - c > 1.0 or v + c < 0.0:
                out.append(f"{name} {q} = {v:.3f} ± {c:.3f} lies outside [0, 1] by more "
                           "than its interval")
    return out


def convergence_counts(n: int, first: int = 4) -> list[int]:
    """Sample counts of the convergence table: doubling from ``first`` up to ``n``."""
    counts = []
    k = first
    while k < n:
        counts.append(k)
        k *= 2
    return [*counts, n] if n >= 1 else []


def convergence(values: Sequence[float], limit: float | None, confidence: float = 0.95,
                seed: int = 0) -> list[dict]:
    """The estimates from the first ``n`` samples for growing ``n``.

    Returns
    -------
    list of dict
        Per count: ``n``, ``P50``, ``P95`` (with their intervals), ``exceedance`` (with
        its interval; None without a limit).
    """
    y = np.asarray(values, dtype=float)
    out = []
    for n in convergence_counts(y.size):
        pct = percentiles(y[:n], confidence, q=(50.0, 95.0), seed=seed)
        out.append({"n": n, **pct,
                    "exceedance": None if limit is None else
                    exceedance(y[:n], limit, confidence)})
    return out
