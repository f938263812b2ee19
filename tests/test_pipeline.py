"""The static correction through to the fields, and two trains on two tracks end to end (the
whole coarse pipeline from one command is checked in tests/test_golden_run.py, on the runs
the golden record makes)."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.cli import run

ROOT = Path(__file__).resolve().parents[1]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=12",
          "--set", "mbs.static_correction=true", "--set", "output.dt=0.004",
          "--set", "output.stress_times=[0.3]"]
comm = MPI.COMM_WORLD


@pytest.mark.slow
@pytest.mark.mpi
def test_static_correction_reaches_the_fields(shared_tmp):
    """A wheelset standing above a sleeper: the rail displacement in fields.h5 equals the MBS one.

    With the static correction the fields are ``Phi (q + q_shift) + X g``: at the
    wheel's node this is the modal part plus the residual flexibility times the
    wheel force, which the MBS used in its contact law. Conicity 0: the MBS
    reports the rail displacement along the contact normal (``w + lambda v``).
    """
    out = shared_tmp / "standing"
    sets = [*COARSE, "--set", "vehicle.x_start=13.2", "--set", "vehicle.x_end=13.2001",
            "--set", "vehicle.speed=0.01", "--set", "output.dt=0", "--set",
            "output.stress_times=[]", "--set", "vehicle.conicity=0"]
    assert run(["modal", str(BASELINE), *sets, "--out", str(out)]) == 0
    assert run(["mbs", str(BASELINE), *sets, "--out", str(out)]) == 0
    assert run(["reconstruct", str(BASELINE), *sets, "--out", str(out)]) == 0
    if comm.rank == 0:
        with h5py.File(out / "modes.h5", "r") as f:
            rails = f["mesh/rail_nodes"][()]
            x = f["mesh/points"][:, 0]
        with h5py.File(out / "mbs.h5", "r") as f:
            w_mbs = f["wheels/rail_displacement"][0]
            q = f["modal/q"][0]
        with h5py.File(out / "fields.h5", "r") as f:
            uz = f["fields/displacement"][0, :, 2]
        with h5py.File(out / "modes.h5", "r") as f:
            phi_z = f["modes/translation"][:, :, 2]
        for r, wheel in ((0, 0), (1, 1)):
            node = rails[r][np.argmin(np.abs(x[rails[r]] - 13.2))]
            assert x[node] == pytest.approx(13.2)
            assert uz[node] == pytest.approx(w_mbs[wheel], rel=1e-6)
            # and the static correction matters: the modal part alone is much smaller
            assert abs(q @ phi_z[:, node]) < 0.7 * abs(uz[node])
    comm.Barrier()


@pytest.mark.slow
@pytest.mark.mpi
def test_two_trains_on_two_tracks_end_to_end(shared_tmp):
    """Two tracks, the second train the other way 0.05 s later, with the static correction
    (its residual flexibility spans all four rails): the run completes on every rank
    count, each train keeps its own rails, and both load the track."""
    out = shared_tmp / "two_tracks"
    sets = [*COARSE, "--set", "track.count=2", "--set", "geometry.ys0=14.0",
            "--set", "train2.t_start=0.05", "--set", "output.stress_times=[]"]
    assert run(["run", str(BASELINE), *sets, "--out", str(out)]) == 0
    if comm.rank == 0:
        with h5py.File(out / "mbs.h5", "r") as f:
            rails = f["wheels/rail_index"][()]
            x = f["wheels/x"][()]
            force = f["wheels/contact_force"][()]
        assert rails.tolist() == [0, 1, 2, 3]
        assert np.all(np.diff(x[:, :2], axis=0) > 0) and np.all(np.diff(x[:, 2:], axis=0) < 0)
        # 0.05 s later at 30 m/s: 1.5 m behind the mirror image of the first train
        mirror = BASELINE_X_LO + BASELINE_X_HI - x[:, 0]
        assert x[:, 2] == pytest.approx(mirror + 1.5, abs=1e-9)
        static = force[0, 0]
        for w in range(4):            # every wheel feels the flexible track: its load varies
            assert np.ptp(force[:, w]) > 1e-4 * static, w
        with h5py.File(out / "modes.h5", "r") as f:
            assert f["mesh/rail_nodes"].shape[0] == 4
        summary = json.loads((out / "assessment.json").read_text())
        assert summary["floors"]["floor 2"]["passed"] is True
        assert "tracks               2, 4 m apart" in (out / "report.md").read_text()
    comm.Barrier()


#: The rails of the baseline: the rigid entry rail's start and the rigid exit rail's end.
BASELINE_X_LO, BASELINE_X_HI = 0.0, 24.6 + 3.0
