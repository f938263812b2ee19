"""Plane-strain P and SV waves meeting a perfectly matched layer at 0, 30, 45 and 60 degrees
(issue 29, item 2): the energy the layer sends back, against the energy of the wave that
meets it (plane-strain slabs through the package's path, :mod:`pml_cases`).

The source is a line source of pure P (four nodal forces pointing away from a node: an
explosion) or pure SV (four forces turning about it: a torque), 15 m above the layer's
inner face; both radiate the same in every direction. The receivers lie 5 m above that face
where the ray reflected by it arrives at the angle of incidence theta: ``x = 20 tan(theta)``
m from the source. The reference is the same slab with the base 52 m deeper (fixed), and
every other face fixed and far enough for its echo to arrive after the window, which ends
when the slowest reflection of 60 degrees has passed (``L / c_S + 2.4 / f_0``, ``L = 20 /
cos(theta)`` the ray's length). The spurious reflection is ``v - v_ref`` at a receiver;
the wave that meets the layer is the reference's direct wave at ``L`` from the source
(receivers beside the source, same spreading). Their energies' ratio is the reflection
coefficient in energy (every reflected and converted wave counted).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import C_S, run_box, slab_mesh

comm = MPI.COMM_WORLD
#: Ricker peak frequency [Hz] and element size [m]: 7 elements per S wavelength at 2.5 f_0.
F0, H = 12.0, 1.0
#: Angles of incidence [deg] (issue 29) and the layer's thickness in elements.
ANGLES = (0.0, 30.0, 45.0, 60.0)
LAYER = 8
#: Source height and receiver height above the layer's inner face (z = -10 m) [m].
Z_FACE, SOURCE_Z, RECEIVER_Z = -10.0, 5.0, -5.0
#: The slab's top [m]: its echo (a P wave in the upper soil) travels 140 m.
Z_TOP = 75
#: The layered site: a lower layer 1.5 x stiffer (c_P, c_S 1.22 x; realistic: stiffer with
#: depth) from z = -7 m down, through the layer; its material enters as the subballast's.
Z_INTERFACE, LOWER_E_FACTOR = -7.0, 1.5


@dataclass(frozen=True)
class Site:
    """Half-width of the slab and the reference's base [m]: the nearest echo of a side or
    base face (a P wave, in the lower layer's speed where there is one) arrives after the
    0.39 s window (homogeneous: 140 m at 346.6 m/s; layered: 170 m at 424.5 m/s)."""

    x_half: int
    z_ref_base: int
    layered: bool

    @property
    def c_p_lower(self) -> float:
        from pml_cases import C_P

        return C_P * math.sqrt(LOWER_E_FACTOR if self.layered else 1.0)

    def extra(self) -> tuple:
        from pml_cases import E

        return (f"materials.subballast.E={LOWER_E_FACTOR * E}",) if self.layered else ()

    def mesh(self, base: float):
        """The slab from ``base`` to :data:`Z_TOP` (the lower layer's part set)."""
        layers = [(Z_INTERFACE - base, "subballast")] if self.layered else None
        return slab_mesh(2 * self.x_half, int(round((Z_TOP - base) / H)), H,
                         origin=(-self.x_half, 0.0, base), layers=layers)


HOMOGENEOUS = Site(90, -70, False)
LAYERED = Site(105, -85, True)
#: The issue's limit: reflected energy below 1 % of the incident.
LIMIT = 0.01


def _geometry():
    """Receivers at the reflection points' angles, and the incident receivers at the
    same ray lengths beside the source; the actual angles (nearest nodes)."""
    depth = (SOURCE_Z - Z_FACE) + (RECEIVER_Z - Z_FACE)
    x = np.round(depth * np.tan(np.radians(ANGLES)) / H) * H
    lengths = np.hypot(x, depth)
    reflected = np.c_[x, np.zeros_like(x), np.full_like(x, RECEIVER_Z)]
    incident = np.c_[-np.round(lengths / H) * H, np.zeros_like(x), np.full_like(x, SOURCE_Z)]
    return np.vstack([reflected, incident]), np.degrees(np.arctan2(x, depth)), lengths


def _line_source(kind: str, amplitude: float = 1e5) -> list:
    """Four forces on the nodes around ``(0, SOURCE_Z)``: outward (P) or turning (SV)."""
    c = np.array([0.0, 0.0, SOURCE_Z])
    offsets = {(H, 0): (0, 1), (-H, 0): (0, -1), (0, H): (2, 1), (0, -H): (2, -1)}
    if kind == "P":
        return [(c + [dx, 0, dz], comp, sign * amplitude)
                for (dx, dz), (comp, sign) in offsets.items()]
    turning = {(H, 0): (2, 1), (-H, 0): (2, -1), (0, H): (0, -1), (0, -H): (0, 1)}
    return [(c + [dx, 0, dz], comp, sign * amplitude)
            for (dx, dz), (comp, sign) in turning.items()]


def reflection_energy(kind: str, layer: int = LAYER, site: Site = HOMOGENEOUS,
                      comm_=comm) -> dict:
    """``R_E`` per angle for a ``kind`` (``"P"``/``"SV"``) source and a layer of
    ``layer`` elements (0: a fixed base at the layer's inner face) on ``site``, with the
    actual angles and the runs' DOFs."""
    receivers, angles, lengths = _geometry()
    t_end = lengths.max() / C_S + 2.4 / F0
    thickness = layer * H
    slab = site.mesh(Z_FACE - thickness)
    faces = {"base": "pml" if layer else "fixed", "x_min": "fixed", "x_max": "fixed",
             "y_min": "free", "y_max": "free"}
    source = _line_source(kind)
    a = run_box(slab, faces, thickness, source, receivers, t_end, F0, comm_,
                plane_strain=True, extra=site.extra())
    from pml_cases import C_P

    ref = run_box(site.mesh(site.z_ref_base), {**faces, "base": "fixed"}, 0.0, source,
                  receivers, t_end, F0, comm_, plane_strain=True, extra=site.extra(),
                  courant=a["dt"] * C_P / H)
    k = len(ANGLES)
    n = min(len(a["t"]), len(ref["t"]))
    spurious = ((a["v"][:n, :k] - ref["v"][:n, :k]) ** 2).sum(axis=(0, 2))
    incident = (ref["v"][:n, k:] ** 2).sum(axis=(0, 2))
    return {"R_E": spurious / incident, "angles": angles, "dofs": (a["dofs"], ref["dofs"]),
            "steps": n - 1, "t_end": t_end}


@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["P", "SV"])
def test_reflected_energy_at_0_to_60_degrees_is_far_below_1_percent(kind):
    """P and SV at 0, 31, 45 and 60 degrees on a layer of 8 elements (the defaults R =
    1e-4, p = 2): reflected energy below 1 % of the incident (the issue) and below 1e-3,
    18x above the
    largest measured (P 3.3e-5 to 4.6e-5, SV 1.9e-5 to 5.6e-5, the largest at 60
    degrees; 5 elements: up to 5.9e-4; ``bench/pml_verification.py`` prints the table).
    On 1 and 2 ranks (``-m mpi``)."""
    out = reflection_energy(kind)
    assert np.all(out["R_E"] < LIMIT) and out["R_E"].max() < 1e-3, out


def test_a_fixed_face_in_place_of_the_layer_reflects_what_the_metric_measures():
    """The same geometry with a fixed base at the layer's inner face: R_E above 0.1 at
    every angle (measured 0.78-1.40: the measure sees a reflection when there is one)."""
    out = reflection_energy("P", layer=0)
    assert np.all(out["R_E"] > 0.1), out


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize("kind", ["P", "SV"])
def test_a_layered_site_whose_lower_layer_runs_through_the_layer(kind):
    """Two layers, the lower 1.5 x stiffer from 3 m above the layer's face down through
    it (its d_max from the lower c_P): R_E below 1 % at every angle and below 1e-3 (the
    waves beyond the critical angle of the interface, 55 degrees, meet the layer as
    evanescent waves)."""
    out = reflection_energy(kind, site=LAYERED)
    assert np.all(out["R_E"] < LIMIT) and out["R_E"].max() < 1e-3, out


@pytest.mark.parametrize("site", [HOMOGENEOUS, LAYERED])
def test_the_window_ends_before_any_fixed_face_echo(site):
    """The geometry's premise: the fastest echo of a fixed face, a P wave from the source
    to the face and back to a receiver (sides and base at the lower layer's speed, the
    top at the upper's), arrives after the window ends."""
    from pml_cases import C_P

    receivers, angles, lengths = _geometry()
    t_end = lengths.max() / C_S + 2.4 / F0
    x, z, half, base = receivers[:, 0], receivers[:, 2], site.x_half, site.z_ref_base
    lower = np.concatenate([(half - x) + half, (x + half) + half,
                            (z - base) + (SOURCE_Z - base)])
    top = (Z_TOP - z) + (Z_TOP - SOURCE_Z)
    assert lower.min() / site.c_p_lower > t_end, (lower.min(), t_end)
    assert top.min() / C_P > t_end, (top.min(), t_end)
    assert math.isclose(angles[-1], 60.26, abs_tol=0.01)
