"""Band slicing of the spectrum: the plan and its proof (pure numpy).

Many modes from one shift and one growing Lanczos basis cost ``n k^2`` in
orthogonalisation and ``n k`` in memory. Band slicing splits ``[0, f_max]`` into
bands; each band has its own shift and factor and a basis only as large as the
band (:mod:`railvib_hpc.modal.band_solve` runs them).

* **Shifts.** The lowest band is solved at shift 0 (so its factor serves the static
  correction, as the single-shift solve does); every other band at the
  eigenvalue midpoint of its edges, ``sigma = (lambda_lo + lambda_hi) / 2``: the
  band is then exactly the eigenvalues within ``r = (lambda_hi - lambda_lo) / 2`` of
  the shift, which shift-invert Lanczos converges first (largest ``|theta|``).
* **Split.** Automatic: ``B = ceil(N / band_modes)`` bands holding about equal numbers
  of modes by Weyl's law (``N(f) ~ f^3`` in three dimensions): edges
  ``f_k = f_max (k / B)^(1/3)``; ``N = N(f_max)`` is the inertia count at ``f_max``.
  Or the user's edges.
* **Proof (Sylvester).** Each band's factorisation of ``K - sigma M`` gives, for free,
  ``N(sigma)``, the number of eigenvalues below its shift (negative pivots); one more
  factorisation gives ``N(f_max)``. Every stretch between two counted points
  ``[sigma_k, sigma_k+1]`` lies in the upper half of band k and the lower half of band
  k + 1, so the distinct eigenvalues found there must number exactly
  ``N(sigma_k+1) - N(sigma_k)`` (:func:`check_counts`): none missed, none twice.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def omega2(f_hz) -> np.ndarray | float:
    """Eigenvalue ``(2 pi f)^2`` of a frequency in Hz."""
    return (2.0 * np.pi * np.asarray(f_hz, dtype=float)) ** 2


def hz(lam) -> np.ndarray | float:
    """Frequency in Hz of an eigenvalue (0 for negative round-off)."""
    return np.sqrt(np.maximum(np.asarray(lam, dtype=float), 0.0)) / (2.0 * np.pi)


@dataclass(frozen=True)
class Band:
    """One band ``[lo_hz, hi_hz]`` and its shift (Hz); ``index`` is 1-based."""

    index: int
    lo_hz: float
    hi_hz: float
    shift_hz: float

    @property
    def sigma(self) -> float:
        return float(omega2(self.shift_hz))

    @property
    def theta_cut(self) -> float:
        """``1 / r``: the band is every eigenvalue with ``|1 / (lambda - sigma)| >= theta_cut``
        (for the lowest band, every eigenvalue below ``hi_hz``)."""
        return 1.0 / max(float(omega2(self.hi_hz)) - self.sigma,
                         self.sigma - float(omega2(self.lo_hz)))

    def label(self, of: int) -> str:
        return (f"band {self.index}/{of} [{self.lo_hz:.2f}, {self.hi_hz:.2f}] Hz, shift "
                f"{self.shift_hz:.2f} Hz")


def weyl_edges(f_lo: float, f_hi: float, n_bands: int) -> list[float]:
    """Inner edges splitting ``[f_lo, f_hi]`` into bands of about equal mode counts by
    Weyl's law ``N(f) ~ f^3``."""
    lo3, hi3 = f_lo**3, f_hi**3
    return [float((lo3 + (hi3 - lo3) * k / n_bands) ** (1.0 / 3.0)) for k in range(1, n_bands)]


def plan_bands(f_max: float, n_total: int, band_modes: int, edges: list[float] | None = None,
               start_hz: float = 0.0, first_index: int = 1, n_below_start: int = 0
               ) -> list[Band]:
    """Bands covering ``[start_hz, f_max]``.

    ``edges``: the user's inner edges (those inside the range are used), else automatic
    (:func:`weyl_edges`, ``ceil((n_total - n_below_start) / band_modes)`` bands).
    The band starting at 0 has shift 0; the others the eigenvalue midpoint of their edges.
    """
    if edges:
        inner = [e for e in sorted(edges) if start_hz < e < f_max]
    else:
        n_bands = max(1, math.ceil(max(n_total - n_below_start, 1) / max(band_modes, 1)))
        inner = weyl_edges(start_hz, f_max, n_bands)
    points = [start_hz, *inner, f_max]
    bands = []
    for k, (lo, hi) in enumerate(zip(points, points[1:])):
        shift = 0.0 if lo == 0.0 else float(hz(0.5 * (omega2(lo) + omega2(hi))))
        bands.append(Band(first_index + k, float(lo), float(hi), shift))
    return bands


def check_counts(points_hz: list[float], counts: list[int], found_hz: np.ndarray,
                 rel_tie: float = 1e-9) -> list[tuple[float, float, int, int]]:
    """Compare the eigenvalues found with the inertia counts, stretch by stretch.

    ``points_hz`` ascending with ``counts[i] = N(points_hz[i])`` (eigenvalues below);
    ``found_hz`` the distinct eigenvalues found. Returns the stretches that disagree as
    ``(lo, hi, expected, found)``. An eigenvalue within ``rel_tie`` of a counted point may
    lie on either side of it (its side is below round-off): counted for whichever side
    makes the totals agree.
    """
    found = np.sort(np.asarray(found_hz, dtype=float))
    bad = []
    for (lo, hi), (n_lo, n_hi) in zip(zip(points_hz, points_hz[1:]), zip(counts, counts[1:])):
        expected = n_hi - n_lo
        strict = int(np.sum((found > lo * (1 + rel_tie)) & (found < hi * (1 - rel_tie))))
        ties = int(np.sum((np.abs(found - lo) <= rel_tie * lo) |
                          (np.abs(found - hi) <= rel_tie * hi)))
        if not strict <= expected <= strict + ties:
            bad.append((float(lo), float(hi), int(expected), strict))
    return bad
