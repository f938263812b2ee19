"""``railvib transient`` checks its own band, ``transient.f_max``, against the mesh.

The tiny coarse thesis model (``mesh.refinement = 0.25``: the subgrade's longest edge
24 m) at ``transient.f_max = 100`` Hz has a fraction of an element per S wavelength. Before,
the run said nothing (the mesh check uses ``mesh.wavelength_hz`` or ``modal.f_max``, both
0) and the studies took ``transient.f_max`` as the band it resolves; now it warns with the
check's numbers, records the band it resolves at the farthest probe, and refuses the run at
``mesh.max_dispersion_error`` as the mesh check does.
"""

from __future__ import annotations

import pytest
from mpi4py import MPI
from transient_cases import BASELINE, TINY, tiny_case

from railvib_hpc.log import Reporter
from railvib_hpc.transient.stage import run_transient_stage

comm = MPI.COMM_WORLD
#: The tiny case's passage cut to 20 ms, no stresses (the check does not depend on them).
SHORT = ["vehicle.x_end=3.3", "output.stress_times=[]"]


def test_an_unresolved_band_is_warned_and_not_claimed(tmp_path, capsys):
    stats = run_transient_stage(tiny_case(*SHORT), tmp_path, comm, Reporter(comm.rank))
    out = capsys.readouterr().out
    assert "transient.f_max = 100" in out and "the mesh cannot resolve the band there" in out
    assert "mesh.min_elements_per_wavelength" in out        # the mesh check's warning too
    top = stats["resolved_up_to_hz"]
    assert 0 < top < 100
    assert f"the results are resolved up to {top:g} Hz at the farthest probe" in out


def test_a_resolved_band_is_claimed(tmp_path, capsys):
    """At 2 Hz the same mesh resolves the band: no warning, ``transient.f_max`` itself."""
    stats = run_transient_stage(tiny_case(*SHORT, "transient.f_max=2"), tmp_path, comm,
                                Reporter(comm.rank))
    out = capsys.readouterr().out
    assert stats["resolved_up_to_hz"] == 2.0
    assert "at transient.f_max = 2 Hz" in out and "cannot resolve" not in out


def test_the_error_limit_refuses_the_run_before_the_integration(tmp_path, capsys):
    from railvib_hpc.cli import run

    sets = [*TINY, *SHORT, "mesh.max_dispersion_error=0.05"]
    code = run(["transient", str(BASELINE), "--out", str(tmp_path),
                *(w for s in sets for w in ("--set", s))])
    captured = capsys.readouterr()
    lines = [ln for ln in captured.err.splitlines() if ln.strip()]
    assert code == 2, captured.err
    assert len(lines) == 1 and lines[0].startswith("railvib transient: error: "
                                                   "transient.f_max = 100: at the farthest")
    assert ">= mesh.max_dispersion_error = 0.05" in lines[0]
    assert "[transient: time integration]" not in captured.out
    assert not (tmp_path / "fields.h5").exists()


@pytest.mark.parametrize("f_max", [80.0, 5.0, 0.5])
def test_third_octave_centres(f_max):
    from railvib_hpc.assess.weighting import third_octave_bands
    from railvib_hpc.mesh.dispersion_check import third_octave_centres

    expected = [float(f) for f in third_octave_bands(1.0, f_max).nominal] if f_max >= 1 \
        else []
    assert third_octave_centres(f_max) == expected
