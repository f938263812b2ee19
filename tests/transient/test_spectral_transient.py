"""``railvib transient`` on a spectral soil (``mesh.order > 1``; docs/spectral.md): the key,
its refusals, the default left as it was, the energy of a closed box, the static start and
the files the trilinear path writes (the boxes: :mod:`spectral_soil_cases`)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from spectral_soil_cases import ABSORBING, BASELINE, SMALL_BOX, probes, small_case

from railvib_hpc.config import Case, load_case
from railvib_hpc.errors import CaseError
from railvib_hpc.io.products import flat_case, hashed_keys
from railvib_hpc.log import Reporter
from railvib_hpc.mesh.stage import MESH_KEYS
from railvib_hpc.transient.stage import STAGE, run_transient_stage
from railvib_hpc.validation import command_problems

comm = MPI.COMM_SELF


def test_the_default_order_is_the_trilinear_element_and_leaves_every_digest():
    case = Case.defaults()
    assert case["mesh.order"] == 1
    assert "mesh.order" not in hashed_keys(flat_case(case.data), MESH_KEYS)
    assert "mesh.order" in hashed_keys(flat_case(case.replace({"mesh.order": 2}).data),
                                       MESH_KEYS)
    assert command_problems(case, "transient") == []


@pytest.mark.parametrize("order, what", [(0, "must be > 0"), (9, "must be <= 8"),
                                         (2.5, "expected an integer")])
def test_an_order_out_of_range_is_refused_in_one_line(order, what):
    with pytest.raises(CaseError, match=what):
        small_case(order=order)


@pytest.mark.parametrize("override, key", [
    ("transient.engine=imex", "transient.engine"),
    ("boundary.base=caughey", "boundary.base"),
    ("damping.model=per_material", "damping.model"),
    ("output.stress_times=[0.01]", "output.stress_times")])
def test_what_the_spectral_path_does_not_take_is_refused_before_meshing(override, key):
    extra = ("boundary.layer_thickness=4",) if "caughey" in override else ()
    case = small_case(*ABSORBING, override, *extra)
    found = command_problems(case, "transient")
    assert [k for k, _, _ in found] == [key] and "mesh.order = 3" in found[0][2]


def test_a_track_or_a_building_is_refused_on_a_spectral_soil():
    case = load_case(None, ["mesh.order=3", "transient.engine=explicit",
                            "modal.lumped_mass=true", "building.present=false"])
    (key, value, allowed), = command_problems(case, "transient")
    assert (key, value) == ("track.count", 1) and "mesh.order = 1" in allowed
    case = load_case(None, ["mesh.order=3", "transient.engine=explicit",
                            "modal.lumped_mass=true", "track.count=0", "load.force=1e5"])
    (key, value, allowed), = command_problems(case, "transient")
    assert (key, value) == ("building.present", True) and "mesh.order = 1" in allowed


def test_the_modal_path_refuses_a_spectral_soil():
    case = load_case(None, ["mesh.order=4"])
    (key, value, allowed), = command_problems(case, "modal")
    assert (key, value) == ("mesh.order", 4) and "railvib transient" in allowed


def test_an_undamped_closed_box_conserves_the_scheme_energy(tmp_path):
    """Base fixed, the sides and the top free, no damping; a point load on for 0.01 s
    runs off the soil's end: from then on the central-difference energy ``1/2 v.(M - dt^2
    / 4 K) v + 1/2 u.K u`` stays constant to round-off."""
    from railvib_hpc.io.stage_protocol import StageRunner

    case = small_case("boundary.base=fixed", "load.start=ramp", "load.ramp_time=0.004",
                      "load.half_width=0", "load.speed=100", "load.x_start=26",
                      "load.x_end=27", "load.t_after=0.1", "output.dt=0.002")
    runner = StageRunner(tmp_path, comm, Reporter(0), (), command="transient")
    stats = runner.run(STAGE, case, record=False, energy_history=True).result.summary
    t, e = np.array(stats["energy"]).T
    after = e[t > 0.012]
    assert after.size > 40 and after[0] > 0
    drift = np.abs(after - after[0]).max() / after[0]
    print(f"\nenergy {after[0]:.6g} J over {t[-1] - 0.012:.3f} s: relative drift {drift:.2e}")
    assert drift < 1e-9


def test_the_static_start_and_the_files(tmp_path):
    """Absorbing faces with springs, the load standing in static equilibrium: the first
    velocities vanish, the settlement beside the load is downwards, and probes.h5,
    transient.h5 and fields.h5 are those the assessment reads."""
    from railvib_hpc.io.formats.fields import check_fields
    from railvib_hpc.io.formats.probes import check_probes
    from railvib_hpc.io.formats.transient import check_transient

    stats = run_transient_stage(small_case(*ABSORBING), tmp_path, comm, Reporter(0))
    p = probes(tmp_path)
    r = p["r_2m"]
    assert np.abs(r["velocity"][0]).max() == 0.0 and r["displacement"][0, 2] < 0
    assert stats["engine"] == "explicit" and stats["order"] == 3
    assert 0.0 < stats["dt"] <= 0.9 * stats["dt_critical"] * (1 + 1e-12)
    assert np.isfinite(r["velocity"]).all() and np.abs(r["velocity"][:, 2]).max() > 0
    for path, check in (("probes.h5", check_probes), ("transient.h5", check_transient),
                        ("fields.h5", check_fields)):
        assert check(tmp_path / path, True) == [], path
    again = run_transient_stage(small_case(*ABSORBING), tmp_path, comm, Reporter(0))
    assert again["reused"]


def test_the_band_the_mesh_resolves_at_its_order_is_reported_and_a_limit_refuses(tmp_path,
                                                                                capsys):
    """The run's own check at transient.f_max on the GLL grid of its order: 3 m elements of
    order 2 at 90 Hz (1.5 points per S wavelength) resolve the band at the farthest probe
    only up to a lower one-third-octave band, which the run records and says (it used to
    record transient.f_max whatever the mesh); with mesh.max_dispersion_error the same run
    is refused in one line, exit code 2, before any file is written. Order 3 at 40 Hz
    resolves its band."""
    import h5py

    from railvib_hpc.cli import run
    from railvib_hpc.io.formats.transient import transient_stats

    coarse = ("transient.f_max=90", "load.x_end=5")
    stats = run_transient_stage(small_case(*coarse, order=2), tmp_path / "coarse", comm,
                                Reporter(0))
    out = capsys.readouterr().out
    assert 0.0 < stats["resolved_up_to_hz"] < 90.0
    with h5py.File(tmp_path / "coarse" / "transient.h5", "r") as f:
        assert transient_stats(f.attrs)["resolved_up_to_hz"] == stats["resolved_up_to_hz"]
    assert "spectral order 2, diagonal GLL mass" in out
    assert f"resolved up to {stats['resolved_up_to_hz']:g} Hz at the farthest probe" in out
    fine = run_transient_stage(small_case("load.x_end=5"), tmp_path / "fine", comm,
                               Reporter(0))
    assert fine["resolved_up_to_hz"] == 40.0
    sets = [a for s in [*SMALL_BOX, "mesh.order=2", *coarse, "mesh.max_dispersion_error=0.05"]
            for a in ("--set", s)]
    capsys.readouterr()
    assert run(["transient", str(BASELINE), "--out", str(tmp_path / "refused"), *sets]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "(order 2: 1.54 points)" in err, err
    assert ">= mesh.max_dispersion_error = 0.05" in err
    assert not (tmp_path / "refused" / "transient.h5").exists()
