"""Which spectral order and element size hold a band's dispersion error at a distance.

:func:`order_advice` asks, for every order ``N``, for the largest element edge ``h`` at
which the worst predicted peak-velocity error (the harmonic bound of
:func:`~.dispersion.peak_velocity_error`) of the S wave and of the Rayleigh wave after
travelling ``distance`` stays below ``target``, and then for the cheapest pair: fewest
DOFs per m^3 (``criterion = "dofs"``), or least work per simulated second (``"cost"``:
DOFs times the measured time per DOF and step, :data:`NS_PER_DOF_AND_STEP`, over the
explicit step, which shrinks with ``N``: :func:`~.dispersion_gll.critical_courant`).

The error of every candidate is the worst of the semidiscretisation (a step tending to 0)
and of central differences at ``step_fraction`` of the grid's critical step (the two ends
of the step range: the time scheme's lead and the lumped mass's lag have opposite signs,
as in the mesh check of the trilinear grid), along the directions where the GLL grid is
worst (:data:`BODY_DIRECTIONS`, :data:`SURFACE_DIRECTIONS`).

Examples
--------
A 20 Hz band in 150 m/s soil, the farthest probe 10 m away, 5 % (the 80 Hz site at 25 m is
in ``docs/spectral.md``: order 4 at 6.0 points per wavelength, 1.24 m elements):

>>> from railvib_hpc.fem.spectral_advice import order_advice
>>> advice = order_advice(20.0, 150.0, 10.0, nu=0.3, target=0.05, orders=(4,))
>>> round(advice["best"]["ppw_s"], 1)                 # points per S wavelength
4.5
"""

from __future__ import annotations

import math
from functools import partial

from .dispersion import _cp_over_cs, elements_needed
from .dispersion_gll import critical_courant, worst_peak_error
from .dispersion_gll_rayleigh import checked_surface_error
from .gll import MAX_ORDER, MIN_ORDER, check_order
from .halfspace import rayleigh_mach_limit

__all__ = ["BODY_DIRECTIONS", "NS_PER_DOF_AND_STEP", "SURFACE_DIRECTIONS", "advice_table",
           "order_advice"]

#: Directions of the S wave's check: the body diagonal is the GLL grid's best direction at
#: every order measured (and its Bloch cell the only 3-D one).
BODY_DIRECTIONS = ("axis", "face_diagonal")
#: Directions of the Rayleigh wave's check by order: both up to order 3 (cheap; at order 2
#: and 5 points per wavelength the face diagonal is the worse, 1.13e-2 against 9.0e-3 per
#: wavelength), the axis from order 4 on, where it is the worse at every size measured
#: (``tests/fem/test_dispersion_gll.py``) and the diagonal's 3-D column costs seconds.
SURFACE_DIRECTIONS = {n: ("axis", "face_diagonal") if n <= 3 else ("axis",)
                      for n in range(MIN_ORDER, MAX_ORDER + 1)}
#: Time per DOF and step of the compiled box kernel plus the central-difference update,
#: one core, by order (``bench/spectral_bench.py --repeat 9`` on this project's 2-core AMD
#: EPYC development machine, 2026-12-07, load average 2.2 from other engineers' jobs: the
#: minimum of 9 steps of 1.3-1.6 M DOFs). Orders 3 and 7 (``N + 1`` a power of two) run at
#: half the speed of their neighbours: there LLVM vectorises the 1-D sums instead of the
#: element lanes. Only the ratios between orders enter the ``"cost"`` criterion.
NS_PER_DOF_AND_STEP = {1: 25.8, 2: 14.4, 3: 24.1, 4: 13.2, 5: 13.1, 6: 12.7, 7: 21.0, 8: 12.2}
#: The explicit engines' fraction of the critical step (``STEP_SAFETY`` of
#: :mod:`railvib_hpc.transient.explicit`).
STEP_FRACTION = 0.9
#: Elements per wavelength searched (``lo``, ``hi`` of :func:`~.dispersion.elements_needed`).
_SEARCH = (0.25, 64.0)


def _needed(order: int, nu: float, wavelengths: float, target: float, courant: float,
            surface: bool) -> float:
    """Fewest elements per wavelength of one wave for the target (inf: none)."""
    schemes = (("none", 0.0), ("central", courant))
    if surface:          # as the mesh check reads it (the 4-point floor, the zone window)
        worst = partial(checked_surface_error, order=order,
                        directions=SURFACE_DIRECTIONS[order])
    else:
        worst = partial(worst_peak_error, order=order, directions=BODY_DIRECTIONS)
    return elements_needed(target, wavelengths, lo=_SEARCH[0], hi=_SEARCH[1], worst=worst,
                           nu=nu, schemes=schemes)


def order_advice(f_max: float, c_s: float, distance: float, nu: float = 0.3,
                 target: float = 0.05, orders=range(MIN_ORDER, MAX_ORDER + 1),
                 criterion: str = "dofs", step_fraction: float = STEP_FRACTION,
                 c_r: float | None = None) -> dict:
    """The cheapest ``(order, h)`` that holds the predicted peak error below ``target``.

    Parameters
    ----------
    f_max
        The band's top frequency [Hz].
    c_s
        The soil's shear-wave speed [m/s].
    distance
        To the farthest probe [m].
    nu
        Poisson's ratio (gives ``c_P``, and ``c_R`` unless given).
    target
        Largest allowed predicted peak-velocity error (0.05: 5 %).
    orders
        The orders to compare (1..8).
    criterion
        ``"dofs"`` (fewest DOFs per m^3) or ``"cost"`` (least core-seconds per m^3 and
        simulated second: DOFs x :data:`NS_PER_DOF_AND_STEP` / the explicit step).
    step_fraction
        The explicit step as a fraction of the grid's critical one.
    c_r
        The Rayleigh wave's speed [m/s] (default: the exact root for ``nu``).

    Returns
    -------
    dict
        ``rows``: per order ``order``, ``epw_s`` and ``epw_r`` (elements per S and
        Rayleigh wavelength needed), ``ppw_s`` (points per S wavelength, ``N epw``), ``h``
        [m], ``dofs_per_m3``, ``dt`` [s], ``core_s_per_m3_s``; ``best`` (the chosen row),
        ``criterion`` and ``wavelengths`` (S and Rayleigh, to the probe).

    Raises
    ------
    ValueError
        For an unknown criterion, a non-positive input or an order out of range.

    Examples
    --------
    >>> a = order_advice(20.0, 150.0, 10.0, orders=(4,), criterion="cost")
    >>> a["best"]["order"], round(a["best"]["h"], 2)
    (4, 6.69)
    """
    if criterion not in ("dofs", "cost"):
        raise ValueError(f"criterion must be 'dofs' or 'cost', got {criterion!r}")
    for name, value in (("f_max", f_max), ("c_s", c_s), ("distance", distance),
                        ("target", target)):
        if not value > 0:
            raise ValueError(f"{name} must be > 0, got {value!r}")
    c_r = c_r or rayleigh_mach_limit(nu) * c_s
    c_p = _cp_over_cs(nu) * c_s
    lengths = {"s": distance * f_max / c_s, "r": distance * f_max / c_r}
    rows = []
    for order in orders:
        n = check_order(order)
        courant = step_fraction * critical_courant(n, nu)
        epw_s = _needed(n, nu, lengths["s"], target, courant, surface=False)
        epw_r = _needed(n, nu, lengths["r"], target, courant, surface=True)
        h = min(c_s / (f_max * epw_s), c_r / (f_max * epw_r))
        dofs = 3.0 * (n / h) ** 3
        dt = courant * h / c_p
        rows.append({"order": n, "epw_s": c_s / (f_max * h), "epw_r": c_r / (f_max * h),
                     "ppw_s": n * c_s / (f_max * h), "h": h, "dofs_per_m3": dofs, "dt": dt,
                     "core_s_per_m3_s": dofs * NS_PER_DOF_AND_STEP[n] * 1e-9 / dt,
                     "s_limited": epw_s * c_r >= epw_r * c_s})
    finite = [r for r in rows if math.isfinite(r["h"]) and r["h"] > 0]
    key = "dofs_per_m3" if criterion == "dofs" else "core_s_per_m3_s"
    best = min(finite, key=lambda r: r[key]) if finite else None
    return {"rows": rows, "best": best, "criterion": criterion,
            "wavelengths": (lengths["s"], lengths["r"]), "target": target}


def advice_table(advice: dict) -> list[str]:
    """The advice as Markdown lines (for the mesh check's report and the docs).

    >>> lines = advice_table(order_advice(20.0, 150.0, 10.0, orders=(4,)))
    >>> lines[0].startswith("| order")
    True
    """
    lines = ["| order | elements per S wavelength | points per S wavelength | h [m] | "
             "limited by | DOFs per m^3 | explicit step [s] | core-s per m^3 and s |",
             "|---|---|---|---|---|---|---|---|"]
    for r in advice["rows"]:
        mark = " (chosen)" if advice["best"] is not None and r is advice["best"] else ""
        lines.append(f"| {r['order']}{mark} | {r['epw_s']:.3g} | {r['ppw_s']:.3g} | "
                     f"{r['h']:.3g} | {'S' if r['s_limited'] else 'Rayleigh'} | "
                     f"{r['dofs_per_m3']:.3g} | {r['dt']:.3g} | {r['core_s_per_m3_s']:.3g} |")
    return lines
