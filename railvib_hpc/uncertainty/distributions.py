"""Marginal distributions of uncertain case keys and their physical-range probability.

One ``[[uncertainty.parameter]]`` table gives ``key``, ``distribution`` and its parameters:

* ``normal``: ``mean``, ``std`` (or ``cov``, the coefficient of variation);
* ``lognormal``: ``mean``, ``std`` (or ``cov``) of the variable itself (not of its log):
  ``sigma_ln^2 = ln(1 + cov^2)``, ``mu_ln = ln(mean) - sigma_ln^2 / 2``;
* ``uniform``: ``low``, ``high``;
* ``truncated_normal``: ``mean``, ``std`` (or ``cov``) of the parent normal, ``low``,
  ``high``.

``mean`` defaults to the case's nominal value of the key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import stats

#: The distributions and the parameters each takes (besides ``key`` and ``name``).
DISTRIBUTIONS: dict[str, tuple[str, ...]] = {
    "normal": ("mean", "std", "cov"),
    "lognormal": ("mean", "std", "cov"),
    "uniform": ("low", "high"),
    "truncated_normal": ("mean", "std", "cov", "low", "high"),
}
#: Keys of one ``[[uncertainty.parameter]]`` table.
PARAMETER_KEYS = ("key", "name", "distribution", "mean", "std", "cov", "low", "high")
#: Largest probability a distribution may put outside the key's physical range (E <= 0,
#: nu >= 0.5, a thickness <= 0...). 1e-6: fewer than one sample in a million would make
#: an invalid model (a study of 10^3-10^4 samples then fails none with near certainty).
PHYSICAL_RANGE_PROBABILITY = 1e-6


@dataclass(frozen=True)
class Marginal:
    """The distribution of one uncertain key.

    Attributes
    ----------
    key
        The case key (``soil.layers[2].c_s`` for a layer's entry).
    name
        Its label in tables (default: the key).
    distribution
        One of :data:`DISTRIBUTIONS`.
    params
        Its parameters (``mean``, ``std``, ``low``, ``high`` as they apply).
    """

    key: str
    name: str
    distribution: str
    params: Mapping[str, float]

    def frozen(self):
        """The SciPy frozen distribution."""
        p = self.params
        if self.distribution == "normal":
            return stats.norm(loc=p["mean"], scale=p["std"])
        if self.distribution == "lognormal":
            s2 = math.log1p((p["std"] / p["mean"]) ** 2)
            return stats.lognorm(s=math.sqrt(s2), scale=math.exp(math.log(p["mean"]) - s2 / 2))
        if self.distribution == "uniform":
            return stats.uniform(loc=p["low"], scale=p["high"] - p["low"])
        a, b = (p["low"] - p["mean"]) / p["std"], (p["high"] - p["mean"]) / p["std"]
        return stats.truncnorm(a, b, loc=p["mean"], scale=p["std"])

    def ppf(self, u: np.ndarray) -> np.ndarray:
        """The values at probabilities ``u`` (the inverse CDF)."""
        return self.frozen().ppf(u)

    def mass_outside(self, low: float | None, high: float | None) -> float:
        """Probability below ``low`` plus above ``high`` (None: no bound); the
        distributions are continuous, so whether a bound itself is allowed does not
        change it."""
        d = self.frozen()
        out = 0.0
        if low is not None:
            out += float(d.cdf(low))            # continuous: P(X <= low) = P(X < low)
        if high is not None:
            out += float(d.sf(high))
        return out


def make_marginal(where: str, entry: Mapping[str, Any], nominal: float | None,
                  problems: list) -> Marginal | None:
    """A :class:`Marginal` from one table (types, required parameters, consistency).

    Parameters
    ----------
    where
        ``uncertainty.parameter[k]`` (for the problems).
    entry
        The table.
    nominal
        The key's nominal value in the case (the default ``mean``).
    problems
        ``(key, value, allowed)`` triples are appended.

    Returns
    -------
    Marginal or None
        None when the table has a problem.
    """
    n_before = len(problems)
    dist = entry.get("distribution")
    if dist not in DISTRIBUTIONS:
        problems.append((f"{where}.distribution", dist,
                         "allowed: " + ", ".join(map(repr, DISTRIBUTIONS))))
        return None
    allowed = DISTRIBUTIONS[dist]
    params: dict[str, float] = {}
    for name, v in entry.items():
        if name in ("key", "name", "distribution"):
            continue
        if name not in allowed:
            problems.append((f"{where}.{name}", v, f"not a parameter of the {dist} "
                             "distribution; it takes: " + ", ".join(allowed)))
            continue
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            problems.append((f"{where}.{name}", v, "expected a finite number"))
            continue
        params[name] = float(v)
    if len(problems) > n_before:
        return None
    if "mean" in allowed:
        if "mean" not in params:
            if nominal is None:
                problems.append((f"{where}.mean", None, "missing (the key has no nominal "
                                 "value to default to)"))
                return None
            params["mean"] = float(nominal)
        if ("std" in params) == ("cov" in params):
            problems.append((f"{where}.std", params.get("std"),
                             f"give exactly one of std and cov for the {dist} distribution"))
            return None
        if "cov" in params:
            cov = params.pop("cov")
            if not cov > 0:                      # the key the user gave, not the std
                problems.append((f"{where}.cov", cov, "must be > 0 (the coefficient of "
                                 "variation, std / mean; a fixed value is no uncertain "
                                 "parameter: leave the table out)"))
                return None
            if params["mean"] == 0:
                problems.append((f"{where}.cov", cov, "gives std = cov x mean = 0: the "
                                 "mean is 0; give std instead"))
                return None
            params["std"] = abs(cov * params["mean"])
        if not params["std"] > 0:
            problems.append((f"{where}.std", params["std"], "must be > 0"))
            return None
        if dist == "lognormal" and not params["mean"] > 0:
            problems.append((f"{where}.mean", params["mean"],
                             "a lognormal variable's mean must be > 0"))
            return None
    if dist in ("uniform", "truncated_normal"):
        missing = [k for k in ("low", "high") if k not in params]
        if missing:
            problems.append((f"{where}.{missing[0]}", None, f"missing: the {dist} "
                             "distribution needs low and high"))
            return None
        if not params["low"] < params["high"]:
            problems.append((f"{where}.high", params["high"],
                             f"must be > low = {params['low']:g}"))
            return None
    key = str(entry.get("key"))
    name = str(entry.get("name") or key)
    return Marginal(key, name, dist, params)
