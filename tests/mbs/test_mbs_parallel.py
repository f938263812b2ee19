"""The mbs stage under MPI: rank 0 computes, every rank returns; static.h5 equals the serial one."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.cli import run

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=8",
          "--set", "mbs.static_correction=true"]
comm = MPI.COMM_WORLD


def _case():
    from railvib_hpc.config import load_case

    return load_case(BASELINE, [s for s in COARSE if s != "--set"])


@pytest.fixture(scope="module")
def par():
    """``railvib modal`` of the coarse case on all ranks, once for both tests below (each
    ran the same modal stage on all ranks itself): the folder, shared by the ranks."""
    import shutil
    import tempfile

    path = tempfile.mkdtemp(prefix="railvib-mbs-") if comm.rank == 0 else None
    path = Path(comm.bcast(path, root=0))
    assert run(["modal", str(BASELINE), *COARSE, "--out", str(path / "par")]) == 0
    yield path / "par"
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(path, ignore_errors=True)


def _serial_modal(folder) -> None:
    """A builder of ``serial_refs`` (tests/conftest.py): the modal stage alone on
    ``MPI.COMM_SELF``."""
    from railvib_hpc.log import Reporter
    from railvib_hpc.modal.stage import run_modal_stage

    run_modal_stage(_case(), folder, MPI.COMM_SELF, Reporter(0))


#: The serial modal stage test_static_solutions_equal_serial compares with
#: (tests/conftest.py: ``serial_refs``, computed side by side with the other modules'
#: references): seconds on one rank, builder.
SERIAL_REFERENCES = {"mbs_coarse_modal": (17.0, _serial_modal)}


@pytest.mark.slow
@pytest.mark.mpi
def test_mbs_on_all_ranks_equals_serial(shared_tmp, par):
    assert run(["mbs", str(BASELINE), *COARSE, "--out", str(par)]) == 0
    comm.Barrier()
    if comm.rank == 0:
        ser = shared_tmp / "ser"
        ser.mkdir()
        # the same static solutions from a serial factorization (same modes file)
        from railvib_hpc.io.stage_protocol import StageRunner
        from railvib_hpc.log import Reporter
        from railvib_hpc.mbs.stage import STAGE, simulate_case

        (ser / "modes.h5").symlink_to(par / "modes.h5")
        case = _case()
        with h5py.File(par / "static.h5", "r") as f:
            x_par = f["static/rail_flexibility"][()]
            t_par = f["static/translation"][:, ::97, :]
        (ser / "static.h5").symlink_to(par / "static.h5")
        # the stage's work on this rank alone, in a context of the folder (no lock taken)
        simulate_case(StageRunner(ser, MPI.COMM_SELF, Reporter(0), command="mbs")
                      .context(case, STAGE))
        with h5py.File(par / "mbs.h5", "r") as a, h5py.File(ser / "mbs.h5", "r") as b:
            for name in ("wheels/contact_force", "modal/q", "static/g", "vehicle/y"):
                np.testing.assert_array_equal(a[name][()], b[name][()])
        assert np.all(np.isfinite(x_par)) and np.abs(t_par).max() > 0


@pytest.mark.slow
@pytest.mark.mpi
def test_static_solutions_equal_serial(par, serial_refs):
    """static.h5 written by 2 ranks (the modal stage of ``par``) equals the one written by
    1 rank (MPI.COMM_SELF, ``serial_refs``)."""
    if comm.rank == 0:
        with h5py.File(par / "static.h5", "r") as a, \
                h5py.File(serial_refs["mbs_coarse_modal"] / "static.h5", "r") as b:
            x1, x2 = a["static/rail_flexibility"][()], b["static/rail_flexibility"][()]
            np.testing.assert_allclose(x1, x2, rtol=1e-9, atol=1e-12 * np.abs(x2).max())
            t1, t2 = a["static/translation"][()], b["static/translation"][()]
            np.testing.assert_allclose(t1, t2, rtol=1e-9, atol=1e-9 * np.abs(t2).max())
    comm.Barrier()


@pytest.mark.mpi
def test_missing_modes_fails_on_every_rank(shared_tmp, capsys):
    assert run(["mbs", str(BASELINE), "--out", str(shared_tmp / "none")]) == 2
