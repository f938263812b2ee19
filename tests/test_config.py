"""Case files: defaults equal the thesis, presets, and every class of invalid input."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from railvib_hpc.cli import run
from railvib_hpc.config import load_case, parse_override
from railvib_hpc.docs import case_reference_markdown, default_case_toml
from railvib_hpc.errors import CaseError
from railvib_hpc.validation import ALL_KEYS

ROOT = Path(__file__).resolve().parents[1]

# Appendix A (APDL) values, ../shared/reference/benchmarks.md section 3.
THESIS_APDL = {
    "geometry.x0": 0.0, "geometry.x1": 3.0, "geometry.x2": 12.6, "geometry.x3": 19.8,
    "geometry.x4": 24.6, "geometry.ys0": 8.25, "geometry.ys1": -4.25, "geometry.ys2": -9.9,
    "geometry.ys3": -17.1, "geometry.ys4": -29.1, "geometry.z0": 0.0, "geometry.z1": 4.8,
    "geometry.z2": 5.3, "geometry.z3": 5.8, "geometry.z4": 6.00424, "geometry.xbb": 16.2,
    "geometry.ybb": -13.5, "geometry.zbb": 2.4, "building.footing_height": 0.6,
    "track.gauge": 2 * 0.75565, "track.rigid_length": 3.0, "track.rail_length": 21.6,
    "track.sleeper_spacing": 0.6, "track.n_sleepers": 37, "track.sleeper_length": 2.5,
    "building.beam_width": 0.6, "building.wall_thickness": 0.3, "building.z_slab1_base": 4.2,
    "building.z_slab2_base": 8.0, "mesh.rail_elements_per_bay": 5,
    "mesh.soil_elements_per_bay": 2, "mesh.soil_elements_per_bay_building": 4,
    "mesh.sleeper_outer_elements": 2, "mesh.sleeper_middle_elements": 4,
    "materials.rail.E": 210e9, "materials.rail.nu": 0.3, "materials.rail.rho": 7700.0,
    "materials.rigid_rail.E": 210e10, "materials.sleeper.E": 64e9,
    "materials.sleeper.nu": 0.25, "materials.sleeper.rho": 2570.0,
    "materials.ballast.E": 260e6, "materials.ballast.nu": 0.25, "materials.ballast.rho": 1800.0,
    "materials.subballast.E": 200e6, "materials.subballast.nu": 0.2,
    "materials.subballast.rho": 1850.0, "materials.subgrade.E": 200e6,
    "materials.subgrade.nu": 0.2, "materials.subgrade.rho": 1850.0,
    "materials.concrete.E": 31e9, "materials.concrete.nu": 0.25, "materials.concrete.rho": 2500.0,
    "pads.kx": 70e8, "pads.ky": 70e8, "pads.kz": 70e8, "pads.cx": 5e5, "pads.cy": 5e5,
    "pads.cz": 5e5, "modal.n_modes": 300, "modal.damping_ratio": 0.03, "vehicle.speed": 30.0,
}
# The APDL's BEAM188 sections from SECDATA (benchmarks.md section 3, 4 digits there).
APDL_SECTIONS = {
    "sections.rail.area": 79.1e-4, "sections.rail.iyy": 3956e-8, "sections.rail.izz": 621e-8,
    "sections.sleeper.area": 495e-4, "sections.sleeper.iyy": 19700e-8,
}
TABLE1 = {
    "materials.ballast.nu": 0.3, "materials.ballast.rho": 1300.0,
    "materials.subballast.nu": 0.35, "materials.subgrade.nu": 0.35,
    "materials.sleeper.rho": 2750.0, "pads.kz": 26.5e7, "pads.cz": 4.6e4,
    "sections.rail.area": 64.5e-4, "sections.rail.iyy": 2010e-8, "sections.rail.izz": 326e-8,
    "sections.rail.shear_coefficient_y": 0.34, "sections.rail.shear_coefficient_z": 0.34,
    "sections.sleeper.area": 513.8e-4, "sections.sleeper.iyy": 18907e-8,
    "sections.sleeper.shear_coefficient_y": 0.83,
}


def test_defaults_equal_thesis_apdl():
    case = load_case(None)
    for key, value in THESIS_APDL.items():
        assert case[key] == pytest.approx(value, rel=1e-12), key
    for key, value in APDL_SECTIONS.items():
        assert case[key] == pytest.approx(value, rel=1.5e-3), key
    assert case["mesh.layout"] == "thesis"


def test_every_preset_value_cites_its_source():
    from railvib_hpc.schema import PRESET_SOURCES, PRESETS, source

    for preset, values in PRESETS.items():
        for key in values:
            assert PRESET_SOURCES[preset].get(key), (preset, key)
    for preset, sources in PRESET_SOURCES.items():
        unknown = [k for k in sources if k not in ALL_KEYS]
        assert not unknown, (preset, unknown)
    # every default that comes from the thesis's model or data names where it comes from
    for key in ALL_KEYS:
        section = key.split(".")[0]
        if section in ("geometry", "track", "building", "materials", "sections", "pads"):
            assert source(key), key
    for key in ("vehicle.wheelset_mass", "vehicle.k_suspension", "vehicle.k_primary",
                "vehicle.k_antiroll", "modal.n_modes", "mesh.layout",
                "irregularity.wavelength_min"):
        assert source(key), key
    assert "SECDATA" in source("sections.rail.j")
    assert "Table I" in source("sections.rail.area", "table1")


def test_baseline_job_file_is_the_defaults():
    case = load_case(ROOT / "jobs" / "thesis_baseline.toml")
    assert case.data == load_case(None).data


def test_generated_docs_are_up_to_date():
    assert (ROOT / "jobs" / "thesis_baseline.toml").read_text() == default_case_toml(), \
        "run `make docs`"
    assert case_reference_markdown() in (ROOT / "docs" / "case_reference.md").read_text(), \
        "run `make docs`"


def test_table1_preset_and_explicit_values_win():
    case = load_case(None, ["case.preset=table1"])
    for key, value in TABLE1.items():
        assert case[key] == pytest.approx(value), key
    case = load_case(None, ["case.preset=table1", "pads.kz=1e9"])
    assert case["pads.kz"] == 1e9 and case["pads.kx"] == pytest.approx(26.5e7)


def test_override_parsing():
    assert parse_override("mesh.refinement=2") == ("mesh.refinement", 2)
    assert parse_override("vehicle.type=moving_force") == ("vehicle.type", "moving_force")
    assert parse_override("modal.lumped_mass=true") == ("modal.lumped_mass", True)
    case = load_case(None, ["mesh.refinement=2", "modal.n_modes=50"])
    assert case["mesh.refinement"] == 2.0 and isinstance(case["mesh.refinement"], float)
    assert case["modal.n_modes"] == 50


def _problem(overrides, toml_text=None, tmp_path=None):
    path = None
    if toml_text is not None:
        path = tmp_path / "case.toml"
        path.write_text(toml_text)
    with pytest.raises(CaseError) as info:
        load_case(path, overrides)
    return info.value.problems


@pytest.mark.parametrize("override, key, fragment", [
    ("geometry.xbbb=1", "geometry.xbbb", "did you mean 'geometry.xbb'"),
    ("materials.balast.E=1e8", "materials.balast.E", "did you mean 'materials.ballast.E'"),
    ("meshes.refinement=2", "meshes.refinement", "did you mean"),
    ("mesh.refinement='fine'", "mesh.refinement", "expected a number"),
    ("track.n_sleepers=3.5", "track.n_sleepers", "expected an integer"),
    ("modal.lumped_mass=1", "modal.lumped_mass", "expected true or false"),
    ("materials.subgrade.E=0", "materials.subgrade.E", "must be > 0"),
    ("materials.concrete.E=-3e9", "materials.concrete.E", "must be > 0"),
    ("materials.ballast.nu=0.5", "materials.ballast.nu", "0 <= nu < 0.5"),
    ("materials.ballast.nu=-0.1", "materials.ballast.nu", "0 <= nu < 0.5"),
    ("materials.rail.rho=0", "materials.rail.rho", "must be > 0"),
    ("building.slab_thickness=-0.2", "building.slab_thickness", "must be > 0"),
    ("sections.rail.area=0", "sections.rail.area", "must be > 0"),
    ("vehicle.type=tram", "vehicle.type", "allowed values"),
    ("track.sleeper_spacing=0.7", "track.sleeper_spacing", "whole bays"),
    ("track.n_sleepers=30", "track.n_sleepers", "must be rail_length / sleeper_spacing + 1"),
    ("geometry.xbb=15.0", "geometry.xbb", "centre of [X2, X3]"),
    ("geometry.x3=30.0", "geometry.x4", "X0 < X1 < X2 < X3 < X4"),
    ("geometry.zbb=5.0", "geometry.zbb", "inside the subgrade"),
    ("geometry.ys2=-3.0", "geometry.ys1", "YS4 < YS3 < YS2 < YS1"),
    ("building.wall_thickness=0.5", "building.wall_thickness", "must not overlap the columns"),
    ("building.z_slab1_base=2.0", "building.z_slab1_base", "building levels overlap"),
    ("building.footing_size=4.0", "building.footing_size", "footings must fit"),
    ("track.sleeper_length=8.0", "track.sleeper_length", "ballast crest"),
    ("mesh.file='nothere.msh'", "mesh.file", "file not found"),
    ("mesh.refinement=0", "mesh.refinement", "must be > 0"),
])
def test_invalid_input_names_key_value_and_allowed(override, key, fragment):
    problems = _problem([override])
    keys = [p[0] for p in problems]
    assert key in keys, problems
    msg = problems[keys.index(key)][2]
    assert fragment in msg, msg


def test_toml_syntax_and_missing_file(tmp_path):
    problems = _problem([], "[mesh\nrefinement = 2", tmp_path)
    assert problems[0][0] == "case file" and "not valid TOML" in problems[0][2]
    with pytest.raises(CaseError, match="file not found"):
        load_case(tmp_path / "missing.toml")


def test_all_problems_reported_at_once(tmp_path):
    problems = _problem([], "[materials.rail]\nE = -1\nnu = 0.7\n[mesh]\nrefinment = 2\n",
                        tmp_path)
    assert {p[0] for p in problems} == {"materials.rail.E", "materials.rail.nu",
                                        "mesh.refinment"}


def test_cli_user_error_exit_code_2_without_traceback(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[materials.subgrade]\nE = -200e6\n")
    assert run(["check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "materials.subgrade.E = -200000000.0" in err and "must be > 0" in err
    assert "Traceback" not in err


def test_cli_study_validates_settings_and_lists_variants(capsys, tmp_path):
    case = str(ROOT / "jobs" / "thesis_baseline.toml")
    assert run(["study", "modes", case, "--out", str(tmp_path),
                "--study-set", "n_modes=[50, -1]", "--study-set", "tolerance=x"]) == 2
    err = capsys.readouterr().err
    assert "invalid settings of the 'modes' study (2 problems)" in err
    assert "study.modes.n_modes = [50, -1]: entry -1 must be > 0" in err
    assert "study.modes.tolerance = 'x': expected a" in err
    assert "Traceback" not in err
    assert run(["check", str(ROOT / "jobs" / "engineering.toml")]) == 0
    for kind, job in (("convergence", "mesh_convergence"), ("modes", "modal_truncation"),
                      ("reflection", "boundary_reflection"), ("speed", "speed_sweep")):
        assert run(["check", str(ROOT / "jobs" / f"{job}.toml")]) == 0
        assert run(["study", kind, str(ROOT / "jobs" / f"{job}.toml"), "--list",
                    "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    for name in ("r1.25", "n300_corrected", "larger", "v60"):
        assert name in out


def test_cli_check_ok_and_console_script():
    assert run(["check", str(ROOT / "jobs" / "thesis_baseline.toml"), "--set",
                "mesh.refinement=2"]) == 0
    proc = subprocess.run([sys.executable, "-m", "railvib_hpc", "check", "nothere.toml"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "case file = 'nothere.toml': file not found" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_every_key_documented():
    for key, p in ALL_KEYS.items():
        assert p.doc and p.unit, key


def test_preset_values_overridden_by_the_file_are_noted():
    case = load_case(ROOT / "jobs" / "thesis_baseline.toml", ["case.preset=table1"])
    assert case["pads.kz"] == 70e8                       # the file's explicit value wins
    assert len(case.notes) == 1 and "pads.kz" in case.notes[0]
    short = load_case(ROOT / "jobs" / "thesis_table1.toml")
    assert short["pads.kz"] == 26.5e7 and short["materials.ballast.rho"] == 1300.0
    assert short.notes == ()


def test_user_probe_roles_are_validated():
    from railvib_hpc.config import load_case

    case = load_case(None, ["output.probes=[1.0, 2.0, 3.0, 4.0, 5.0, 6.0]",
                            "output.probe_roles=[floor, ground]"])
    assert case["output.probe_roles"] == ["floor", "ground"]
    with pytest.raises(CaseError, match=r"output.probe_roles = \['roof'\]: unknown entries"):
        load_case(None, ["output.probes=[1.0, 2.0, 3.0]", "output.probe_roles=[roof]"])
    with pytest.raises(CaseError, match=r"one role per point of output\.probes"):
        load_case(None, ["output.probes=[1.0, 2.0, 3.0]",
                         "output.probe_roles=[floor, wall]"])


def test_a_closed_output_pipe_is_not_an_internal_error(tmp_path):
    """`railvib check CASE | head -1` closes the pipe early: exit 141, no crash log."""
    import subprocess
    import sys
    from pathlib import Path

    case = Path(__file__).resolve().parents[1] / "jobs" / "thesis_baseline.toml"
    proc = subprocess.Popen([sys.executable, "-m", "railvib_hpc", "check", str(case),
                             "--set", "trench.type=open", "--set", "trench.width=0.6",
                             "--set", "trench.depth=2", "--set", "trench.distance=7"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    proc.stdout.close()                       # the reader goes away before any output
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141, err
    assert "internal error" not in err and not (tmp_path / "results").exists()
