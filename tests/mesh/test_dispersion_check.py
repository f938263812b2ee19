"""The mesh check's numerical dispersion at the farthest probe (issue 28, item 2)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from scipy.optimize import brentq

from railvib_hpc.cli import run
from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError, MeshError, UserError
from railvib_hpc.fem.boundary import wave_speeds
from railvib_hpc.fem.dispersion_rayleigh import worst_surface_error
from railvib_hpc.mesh.dispersion_check import (
    EXPLICIT_STEP_SAFETY,
    UNRESOLVED_PHASE,
    DispersionError,
    dispersion_report,
    farthest_probe,
    rayleigh_ratio,
)

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
PROBES = {"near": [10.0, -5.0, 0.0], "far": [10.0, -25.0, 0.0], "other_side": [10.0, 8.0, 0.0]}


def _case(**changes) -> Case:
    return Case.defaults().replace({"mesh.wavelength_hz": 30.0, **changes})


def _subgrade(case: Case) -> tuple[float, float]:
    mat = case["materials.subgrade"]
    return float(wave_speeds(mat["E"], mat["nu"], mat["rho"])[1]), float(mat["nu"])


def _quality(h: float) -> dict:
    return {"max_edge_per_soil_part": {"subgrade": h, "ballast": 5.0 * h}}


def _edge(case: Case, epw: float) -> float:
    """The edge with ``epw`` elements per S wavelength of the subgrade at the band."""
    c_s, _ = _subgrade(case)
    return c_s / (case["mesh.wavelength_hz"] * epw)


def test_no_band_no_check():
    assert dispersion_report(_quality(1.0), Case.defaults(), PROBES) is None


def test_the_farthest_probe_from_either_track():
    one = Case.defaults()
    assert farthest_probe(one, PROBES) == ("far", 25.0, 1)
    two = one.replace({"track.count": 2, "track.spacing": 4.0, "geometry.ys0": 14.0})
    assert farthest_probe(two, PROBES) == ("far", 29.0, 2)
    user = two.replace({"output.probes": [10.0, -40.0, 0.0]})
    assert farthest_probe(user, PROBES) == ("user_1", 44.0, 2)


def test_rayleigh_ratio_is_the_root_of_the_rayleigh_equation():
    for nu in (0.0, 0.2, 0.3, 0.45, 0.49):
        k2 = (1 - 2 * nu) / (2 * (1 - nu))              # (c_S / c_P)^2

        def rayleigh(x, k2=k2):                         # x = (c_R / c_S)^2
            return x**3 - 8 * x**2 + (24 - 16 * k2) * x - 16 * (1 - k2)

        exact = math.sqrt(brentq(rayleigh, 0.5, 0.99))
        assert rayleigh_ratio(nu) == pytest.approx(exact, rel=0.015)


def test_the_explicit_engines_safety_factor_is_the_engines():
    from railvib_hpc.transient.explicit import STEP_SAFETY

    assert EXPLICIT_STEP_SAFETY == STEP_SAFETY


def test_report_line_is_the_rayleigh_wave_in_the_worst_direction():
    """The predicted error is the grid's Rayleigh relation over the distance in Rayleigh
    wavelengths, the worst direction and time step end."""
    case = _case()
    c_s, nu = _subgrade(case)
    f, h = 30.0, _edge(case, 20.0)
    rep = dispersion_report(_quality(h), case, PROBES)
    c_r = rayleigh_ratio(nu) * c_s
    dt = 1.0 / (case["transient.steps_per_period"] * case["transient.f_max"])
    c_p = float(wave_speeds(*(case["materials.subgrade"][k] for k in ("E", "nu", "rho")))[0])
    expected = worst_surface_error(c_r / (f * h), 25.0 * f / c_r, nu, "consistent",
                                   (("none", 0.0), ("generalized_alpha", c_p * dt / h)))[0]
    assert rep["probe"] == "far" and rep["part"] == "subgrade"
    assert rep["error"] == pytest.approx(expected, rel=1e-12)
    assert rep["parts"]["subgrade"]["epw"] == pytest.approx(20.0)
    assert "ballast" not in rep["parts"]                   # crossed over a few metres only
    assert "predicted peak-velocity error" in rep["line"] and "far (25 m" in rep["line"]
    assert rep["error"] < 0.05 and rep["warnings"] == []


def test_a_coarse_grid_warns_with_the_elements_that_meet_the_target():
    case = _case()
    rep = dispersion_report(_quality(_edge(case, 10.0)), case, PROBES)
    assert rep["error"] > 0.05 and len(rep["warnings"]) == 1
    need = rep["needed"]
    assert f"raise mesh.elements_per_wavelength to >= {math.ceil(need * 10) / 10:g}" \
        in rep["warnings"][0]
    # the advice holds: that many elements meet the target, a few per cent fewer do not
    assert dispersion_report(_quality(_edge(case, need)), case, PROBES)["warnings"] == []
    assert dispersion_report(_quality(_edge(case, 0.97 * need)), case, PROBES)["warnings"]


def test_a_band_the_mesh_cannot_resolve_is_refused_in_one_line():
    case = _case()
    with pytest.raises(DispersionError) as info:
        dispersion_report(_quality(_edge(case, 3.0)), case, PROBES)
    msg = str(info.value)
    assert isinstance(info.value, MeshError) and isinstance(info.value, UserError)
    assert info.value.exit_code == 2 and "\n" not in msg
    assert msg.startswith("mesh.wavelength_hz = 30: at the farthest probe far (25 m from "
                          "track 1) subgrade has 3 elements per S wavelength")
    assert f"allowed: less than {UNRESOLVED_PHASE:g} period" in msg
    need = float(msg.split("mesh.elements_per_wavelength to >= ")[1].split()[0])
    assert dispersion_report(_quality(_edge(case, need)), case, PROBES)["phase_periods"] \
        < UNRESOLVED_PHASE
    # max_dispersion_error = 0 does not lift this refusal; nothing is checked without a band
    with pytest.raises(DispersionError):
        dispersion_report(_quality(_edge(case, 3.0)), case.replace(
            {"mesh.max_dispersion_error": 0.0}), PROBES)


def test_max_dispersion_error_refuses_what_it_does_not_accept():
    case = _case(**{"mesh.max_dispersion_error": 0.05})
    with pytest.raises(DispersionError) as info:
        dispersion_report(_quality(_edge(case, 12.0)), case, PROBES)
    msg = str(info.value)
    assert "predicted peak-velocity error" in msg and "mesh.max_dispersion_error = 0.05" in msg
    need = float(msg.split("mesh.elements_per_wavelength to >= ")[1].split()[0])
    assert dispersion_report(_quality(_edge(case, need)), case, PROBES)["error"] < 0.05


def test_the_explicit_engine_is_bounded_by_its_semidiscretisation():
    """Lumped mass and central differences: the step only lowers the lag, so the worst end
    is the semidiscretisation (the modal path's error)."""
    case = _case(**{"transient.engine": "explicit", "modal.lumped_mass": True})
    rep = dispersion_report(_quality(_edge(case, 20.0)), case, PROBES)
    c_s, nu = _subgrade(case)
    c_r = rayleigh_ratio(nu) * c_s
    h = _edge(case, 20.0)
    semi = worst_surface_error(c_r / (30.0 * h), 25.0 * 30.0 / c_r, nu, "lumped")[0]
    assert rep["error"] == pytest.approx(semi, rel=1e-12)
    assert "none" in rep["line"]


def test_the_key_is_a_fraction_and_enters_no_digest():
    from railvib_hpc.io.products import STAGE_FILES, inputs_hash

    with pytest.raises(CaseError, match=r"mesh\.max_dispersion_error = 1\.5"):
        Case.defaults().replace({"mesh.max_dispersion_error": 1.5})
    a, b = Case.defaults(), Case.defaults().replace({"mesh.max_dispersion_error": 0.05})
    for name in STAGE_FILES:
        assert inputs_hash(a, name) == inputs_hash(b, name), name


def test_the_mesh_stage_refuses_before_writing_the_mesh(tmp_path, capsys):
    """The thesis layout (4 m across the track far from it) cannot carry 40 Hz to
    ground_far: exit code 2, one line, no mesh.h5 or mesh.msh left."""
    out = tmp_path / "res"
    code = run(["mesh", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
                "mesh.wavelength_hz=40", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(lines) == 1 and "mesh.wavelength_hz = 40: at the farthest probe ground_far" \
        in lines[0]
    assert not (out / "mesh.h5").exists() and not (out / "mesh.msh").exists()


@pytest.mark.slow
def test_a_reused_mesh_is_checked_again(tmp_path, capsys):
    """output.probes and mesh.max_dispersion_error are no mesh inputs: a far probe and a
    limit added to a current mesh are checked on reuse; the report line is printed."""
    out = tmp_path / "res"
    args = ["mesh", str(BASELINE), "--set", "mesh.refinement=0.5", "--set",
            "mesh.wavelength_hz=2", "--out", str(out)]
    assert run(args) == 0
    assert "numerical dispersion at the farthest probe, ground_far" in capsys.readouterr().out
    stamp = (out / "mesh.h5").stat().st_mtime_ns
    assert run(args + ["--set", "output.probes=[16.2, -400.0, 4.8]", "--set",
                       "mesh.max_dispersion_error=0.05"]) == 2
    assert "farthest probe user_1" in capsys.readouterr().err
    assert (out / "mesh.h5").stat().st_mtime_ns == stamp
