"""How many base points a Saltelli design needs before its Sobol' indices are estimates.

The uncertainty study reports Sobol' indices only from
:data:`railvib_hpc.uncertainty.statistics.MIN_SOBOL_BASE_SAMPLES` base points on
(:func:`~railvib_hpc.uncertainty.statistics.sobol_doubts`). This bench measures the error of
the study's own estimators (:func:`~railvib_hpc.uncertainty.statistics.sobol_indices`, SALib
with the Saltelli design of :func:`~railvib_hpc.uncertainty.sampling.unit_design`) against
exact indices, for growing N, over independent seeds:

* the Ishigami function (a = 7, b = 0.1; Ishigami & Homma 1990), strongly non-linear with
  an interaction, the usual hard test;
* a linear function ``x1 + 0.5 x2 + 0.1 x3`` of uniform inputs on [-pi, pi], the kind of
  smooth response a peak acceleration is of a few stiffnesses and a speed.

It prints, per N, the RMS and the largest error of S1 and ST over all inputs and seeds,
and how many estimates lie outside [0, 1] by more than their bootstrap interval.

Usage::

    python bench/sobol_sample_size.py [--seeds 20] [--n 2 4 8 16 32 64 128 256]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np

from railvib_hpc.uncertainty.sampling import unit_design
from railvib_hpc.uncertainty.statistics import sobol_indices

#: The Ishigami function's constants (Ishigami & Homma 1990; Sobol' & Levitan 1999).
ISHIGAMI_A, ISHIGAMI_B = 7.0, 0.1
#: The linear test function's coefficients.
LINEAR = np.array([1.0, 0.5, 0.1])
NAMES = ["x1", "x2", "x3"]


def ishigami_exact() -> dict[str, tuple[float, float]]:
    """The exact (S1, ST) of the Ishigami function."""
    a, b = ISHIGAMI_A, ISHIGAMI_B
    v1 = 0.5 * (1 + b * np.pi**4 / 5) ** 2
    v2 = a**2 / 8
    v13 = b**2 * np.pi**8 * (1 / 18 - 1 / 50)
    var = v1 + v2 + v13
    return {"x1": (v1 / var, (v1 + v13) / var), "x2": (v2 / var, v2 / var),
            "x3": (0.0, v13 / var)}


def linear_exact() -> dict[str, tuple[float, float]]:
    """The exact indices of the linear function (no interaction: S1 = ST)."""
    share = LINEAR**2 / (LINEAR**2).sum()
    return {n: (float(s), float(s)) for n, s in zip(NAMES, share)}


def errors(n: int, seeds: int, f, exact) -> tuple[float, float, int, int]:
    """RMS and largest |error| of S1 and ST, and the count outside [0, 1] beyond the
    interval, of all inputs over ``seeds`` designs of ``n`` base points."""
    err, outside, total = [], 0, 0
    for seed in range(seeds):
        x = -np.pi + 2 * np.pi * unit_design("sobol", n, 3, seed=seed)
        got = sobol_indices(NAMES, f(x), seed=seed)
        for name, (s1, st) in exact.items():
            for q, true in (("S1", s1), ("ST", st)):
                v, c = got[name][q], got[name][f"{q}_conf"]
                err.append(v - true)
                outside += bool(v - c > 1.0 or v + c < 0.0)
                total += 1
    e = np.asarray(err)
    return float(np.sqrt(np.mean(e**2))), float(np.abs(e).max()), outside, total


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--seeds", type=int, default=20)
    p.add_argument("--n", type=int, nargs="+", default=[2, 4, 8, 16, 32, 64, 128, 256])
    args = p.parse_args()
    warnings.filterwarnings("ignore")          # SALib's note on small designs
    a, b = ISHIGAMI_A, ISHIGAMI_B

    def ishigami(x):
        return np.sin(x[:, 0]) + a * np.sin(x[:, 1]) ** 2 + b * x[:, 2] ** 4 * np.sin(x[:, 0])

    def linear(x):
        return x @ LINEAR

    print(f"{'N':>5}  {'Ishigami RMS':>12} {'max':>7} {'outside':>8}   "
          f"{'linear RMS':>10} {'max':>7} {'outside':>8}   ({args.seeds} seeds, S1 and ST)")
    for n in args.n:
        ri, mi, oi, t = errors(n, args.seeds, ishigami, ishigami_exact())
        rl, ml, ol, _ = errors(n, args.seeds, linear, linear_exact())
        print(f"{n:>5}  {ri:>12.3f} {mi:>7.3f} {oi:>4d}/{t:<3d}   {rl:>10.3f} {ml:>7.3f} "
              f"{ol:>4d}/{t:<3d}")


if __name__ == "__main__":
    main()
