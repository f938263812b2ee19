"""Richardson extrapolation and the grid convergence index (GCI) of a mesh sequence.

The procedure is the one of Celik et al. (2008), *Procedure for estimation and reporting of
uncertainty due to discretization in CFD applications*, J. Fluids Eng. 130(7), 078001,
which allows non-constant refinement ratios:

* representative mesh size ``h = (1 / N)^(1/3)`` for ``N`` unknowns (3-D), refinement ratios
  ``r21 = h2 / h1``, ``r32 = h3 / h2`` (1: finest);
* observed order ``p`` from three levels, the root of
  ``p ln r21 = ln|e32 / e21| + ln((r21^p - s) / (r32^p - s))`` with ``e32 = f3 - f2``,
  ``e21 = f2 - f1`` and ``s = sign(e32 / e21)`` (``s < 0``: oscillatory convergence);
* extrapolated value ``f_ext = (r21^p f1 - f2) / (r21^p - 1)``, relative error of the finest
  level ``|f1 - f_ext| / |f_ext|`` and ``GCI_fine = 1.25 |(f1 - f2) / f1| / (r21^p - 1)``.

For ``f(h) = f0 + C h^p`` the order and the extrapolated value are recovered exactly (to
round-off) for any ratios; the tests check this.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

#: Observed orders outside this range are reported but not trusted for the extrapolation.
ORDER_RANGE = (0.5, 8.0)


@dataclass
class Extrapolation:
    """Richardson estimate for one quantity on the finest mesh.

    Attributes
    ----------
    value
        Finest-level value ``f1``.
    extrapolated
        ``f_ext`` with ``order`` (None when all values are zero).
    order
        Order used for ``f_ext``: the observed one when ``basis == "observed"``, else the
        assumed formal order.
    observed_order
        The order observed from the three finest levels (None: fewer levels, vanishing
        differences or no root).
    oscillatory
        True when the three finest values oscillate (``s < 0``).
    basis
        ``"observed"``: three monotone levels with an observed order inside
        :data:`ORDER_RANGE`, ``error = |f1 - f_ext| / |f_ext|``; ``"assumed"``: two levels,
        the formal order is assumed, same error formula; ``"unreliable"``: three levels but
        oscillating or with an order outside the range, ``error`` is the largest of the
        assumed-order estimate and the last two relative changes (conservative).
    error
        Relative error estimate of the finest level.
    gci
        ``GCI_fine = 1.25 |(f1 - f2)/f1| / (r21^p - 1)`` with ``order``.
    last_change
        ``|f1 - f2| / |f1|``.
    """

    value: float
    extrapolated: float | None
    order: float
    observed_order: float | None
    oscillatory: bool
    basis: str
    error: float
    gci: float | None
    last_change: float

    def as_dict(self) -> dict:
        """JSON-ready dict."""
        return asdict(self)


def _rel(a: float, b: float) -> float:
    """``|a - b| / |b|`` (0 when both vanish, inf when only ``b`` does)."""
    if b == 0:
        return 0.0 if a == 0 else math.inf
    return abs(a - b) / abs(b)


def mesh_sizes(n_unknowns: Sequence[float], dim: int = 3) -> np.ndarray:
    """Representative mesh sizes ``h = N^(-1/dim)`` (relative; only ratios matter)."""
    n = np.asarray(n_unknowns, dtype=float)
    if np.any(n <= 0):
        raise ValueError(f"numbers of unknowns must be positive, got {list(n)}")
    return n ** (-1.0 / dim)


def _residual(p: float, ratio: float, r21: float, r32: float, s: float) -> float:
    """``p ln r21 - ln|e32/e21| - ln((r21^p - s)/(r32^p - s))``."""
    a, b = r21**p - s, r32**p - s
    if a <= 0 or b <= 0:
        return float("nan")
    return p * math.log(r21) - math.log(ratio) - math.log(a / b)


def observed_order(f1: float, f2: float, f3: float, r21: float, r32: float,
                   p_max: float = 20.0) -> float | None:
    """Observed order of convergence from three levels (1: finest), any refinement ratios.

    Parameters
    ----------
    f1, f2, f3
        Values on the fine, medium and coarse mesh.
    r21, r32
        Refinement ratios ``h2/h1`` and ``h3/h2`` (> 1).
    p_max
        Largest order searched.

    Returns
    -------
    float or None
        The order, or None when the differences vanish or no root exists in (0, p_max].
    """
    if not (r21 > 1.0 and r32 > 1.0):
        raise ValueError(f"refinement ratios must exceed 1, got r21 = {r21}, r32 = {r32}")
    e21, e32 = f2 - f1, f3 - f2
    scale = max(abs(f1), abs(f2), abs(f3), 1e-300)
    if abs(e21) <= 1e-14 * scale or abs(e32) <= 1e-14 * scale:
        return None
    ratio = abs(e32 / e21)
    s = math.copysign(1.0, e32 / e21)
    if math.isclose(r21, r32, rel_tol=1e-12) and s > 0:
        p = math.log(ratio) / math.log(r21)
        return p if 0.0 < p <= p_max else None
    # bracket the root on a grid, then bisect (robust for any ratios)
    grid = np.concatenate([np.linspace(1e-3, 1.0, 50), np.linspace(1.0, p_max, 400)[1:]])
    vals = np.array([_residual(p, ratio, r21, r32, s) for p in grid])
    for k in range(len(grid) - 1):
        a, b = vals[k], vals[k + 1]
        if not (np.isfinite(a) and np.isfinite(b)):
            continue
        if a == 0.0:
            return float(grid[k])
        if a * b < 0:
            lo, hi, flo = grid[k], grid[k + 1], a
            for _ in range(200):
                mid = 0.5 * (lo + hi)
                fm = _residual(mid, ratio, r21, r32, s)
                if fm == 0.0 or hi - lo < 1e-15 * max(1.0, mid):
                    return float(mid)
                if (fm < 0) == (flo < 0):
                    lo, flo = mid, fm
                else:
                    hi = mid
            return float(0.5 * (lo + hi))
    return None


def extrapolate(values: Sequence[float], sizes: Sequence[float],
                formal_order: float = 2.0) -> Extrapolation:
    """Richardson estimate of the finest level from a sequence of levels.

    Parameters
    ----------
    values
        Quantity on each level, ordered from coarse to fine (at least two levels).
    sizes
        Representative mesh sizes of the levels (same order, decreasing), e.g. from
        :func:`mesh_sizes`.
    formal_order
        Order assumed with two levels or when the observed order is unreliable.

    Returns
    -------
    Extrapolation
    """
    f = [float(v) for v in values]
    h = [float(v) for v in sizes]
    if len(f) != len(h) or len(f) < 2:
        raise ValueError("need at least two levels with one size each")
    if any(b >= a for a, b in zip(h, h[1:])):
        raise ValueError(f"mesh sizes must decrease from coarse to fine, got {h}")
    f1, f2 = f[-1], f[-2]
    r21 = h[-2] / h[-1]
    last = _rel(f2, f1)
    p_obs, oscillatory = None, False
    if len(f) >= 3:
        f3 = f[-3]
        oscillatory = (f3 - f2) * (f2 - f1) < 0
        p_obs = observed_order(f1, f2, f3, r21, h[-3] / h[-2])
    if len(f) == 2:
        basis = "assumed"
    elif (p_obs is not None and not oscillatory
          and ORDER_RANGE[0] <= p_obs <= ORDER_RANGE[1]):
        basis = "observed"
    elif p_obs is None and f1 == f2 == f[-3]:
        basis = "observed"                      # identical levels: converged exactly
    else:
        basis = "unreliable"
    p = p_obs if (basis == "observed" and p_obs is not None) else formal_order
    ext = f1 if f1 == f2 else (r21**p * f1 - f2) / (r21**p - 1.0)
    error = _rel(f1, ext)
    if basis == "unreliable":
        error = max(error, last, _rel(f[-3], f1))
    gci = 1.25 * last / (r21**p - 1.0) if math.isfinite(last) else None
    return Extrapolation(value=f1, extrapolated=ext, order=float(p), observed_order=p_obs,
                         oscillatory=bool(oscillatory), basis=basis, error=float(error),
                         gci=gci, last_change=float(last))
