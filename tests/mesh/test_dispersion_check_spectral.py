"""The mesh check on a spectral soil (``mesh.order > 1``): the GLL grid's own Rayleigh
relation at the case's order (:func:`~railvib_hpc.fem.dispersion_gll_rayleigh.
checked_surface_error`), its refusal of a mesh too coarse for the band at that order, and
its advice at that order and the next (docs/spectral.md)."""

from __future__ import annotations

from pathlib import Path

import pytest

from railvib_hpc.config import Case
from railvib_hpc.fem.boundary import wave_speeds
from railvib_hpc.fem.dispersion_gll import critical_courant
from railvib_hpc.fem.dispersion_gll_rayleigh import (
    MIN_POINTS_PER_WAVELENGTH,
    checked_surface_error,
)
from railvib_hpc.fem.spectral_advice import SURFACE_DIRECTIONS
from railvib_hpc.mesh.dispersion_check import (
    EXPLICIT_STEP_SAFETY,
    DispersionError,
    dispersion_report,
    rayleigh_ratio,
    soil_grid,
)

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
#: The farthest probe 25 m from the track (the 80 Hz site's distance).
PROBES = {"far": [10.0, -25.0, 0.0]}
#: The band of the checks [Hz].
BAND = 30.0


def _case(order: int, **changes) -> Case:
    """The thesis defaults on the explicit engine (the spectral soil's) at ``order``."""
    return Case.defaults().replace({"mesh.wavelength_hz": BAND, "mesh.order": order,
                                    "transient.engine": "explicit",
                                    "modal.lumped_mass": True, **changes})


def _subgrade(case: Case) -> tuple[float, float, float]:
    mat = case["materials.subgrade"]
    c_p, c_s = (float(v) for v in wave_speeds(mat["E"], mat["nu"], mat["rho"]))
    return c_p, c_s, float(mat["nu"])


def _quality(case: Case, epw: float) -> dict:
    """The subgrade's longest edge with ``epw`` elements per S wavelength at the band."""
    return {"max_edge_per_soil_part": {"subgrade": _subgrade(case)[1] / (BAND * epw)}}


def test_the_soil_grid_is_the_cases_element():
    assert soil_grid(_case(1)).order == 1 and soil_grid(_case(1)).mass == "lumped mass"
    grid = soil_grid(_case(4))
    assert grid.order == 4 and grid.mass == "spectral order 4, diagonal GLL mass"
    assert grid.critical(0.3) == critical_courant(4, 0.3)


def test_the_check_reads_the_gll_relation_of_the_cases_order():
    """At 1.5 elements (6 points at order 4) per S wavelength and 25 m the order-4 check
    predicts the GLL relation's error (the explicit engine at 0.9 of the GLL grid's critical
    step, the worse end) and passes; the same elements as trilinear ones cannot carry the
    band there and are refused."""
    case = _case(4)
    _, c_s, nu = _subgrade(case)
    rep = dispersion_report(_quality(case, 1.5), case, PROBES)
    c_r = rayleigh_ratio(nu) * c_s
    h = c_s / (BAND * 1.5)
    schemes = (("none", 0.0), ("central", EXPLICIT_STEP_SAFETY * critical_courant(4, nu)))
    expected = checked_surface_error(c_r / (BAND * h), 25.0 * BAND / c_r, nu, 4, schemes,
                                     directions=SURFACE_DIRECTIONS[4])[0]
    assert rep["order"] == 4 and rep["error"] == pytest.approx(expected, rel=1e-12)
    assert rep["error"] < 0.05 and rep["warnings"] == []
    assert "(order 4: 6 points)" in rep["line"] and "spectral order 4" in rep["line"]
    with pytest.raises(DispersionError, match="the mesh cannot resolve the band"):
        dispersion_report(_quality(case, 1.5), _case(1), PROBES)


def test_a_mesh_too_coarse_for_its_order_is_refused_and_the_advice_holds():
    """Order 4 at 0.75 elements (3 points) per S wavelength: below the 4 points the GLL grid
    resolves, one line (exit code 2) with the elements needed at order 4 and at order 5;
    each advised size passes the check at its order."""
    case = _case(4)
    with pytest.raises(DispersionError) as info:
        dispersion_report(_quality(case, 0.75), case, PROBES)
    msg = str(info.value)
    assert info.value.exit_code == 2 and "\n" not in msg
    assert "subgrade has 0.75 elements per S wavelength (order 4: 3 points)" in msg
    assert f"fewer than {MIN_POINTS_PER_WAVELENGTH:g}" in msg
    need = float(msg.split("mesh.elements_per_wavelength to >= ")[1].split()[0])
    higher = float(msg.split("mesh.order = 5 with mesh.elements_per_wavelength >= ")[1]
                   .split()[0])
    assert "DOFs per m^3" in msg and higher < need
    assert dispersion_report(_quality(case, need), case, PROBES)["phase_periods"] < 0.5
    assert dispersion_report(_quality(case, higher), _case(5), PROBES)["phase_periods"] < 0.5


def test_max_dispersion_error_refuses_at_the_cases_order():
    """The same mesh, 1.2 elements per S wavelength, passes a 1 % limit at order 5 (0.45 %
    predicted) and is refused at order 4 (1.4 %)."""
    limit = {"mesh.max_dispersion_error": 0.01}
    assert dispersion_report(_quality(_case(5), 1.2), _case(5, **limit), PROBES)["error"] < 0.01
    with pytest.raises(DispersionError, match=r"order 4: 4\.8 points.*>= "
                                              r"mesh.max_dispersion_error = 0.01"):
        dispersion_report(_quality(_case(4), 1.2), _case(4, **limit), PROBES)
