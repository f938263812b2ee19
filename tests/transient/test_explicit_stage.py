"""``railvib transient`` with ``transient.engine = "explicit"`` (issue 28): against the direct
path on the thesis model, on 1 and 2 ranks, and its bad input."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE, TINY

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD
#: The tiny thesis case with the lumped mass both engines use here.
SETS = [a for s in (*TINY, "modal.lumped_mass=true") for a in ("--set", s)]
EXPLICIT = ["--set", "transient.engine=explicit"]
#: The direct path's step for the reference: 1/10 of its automatic 5e-4 s, so that its own
#: time-discretisation error (second order: ~5 % at 5e-4 s, measured) is ~0.05 %.
DIRECT_DT = ["--set", "transient.dt=5e-05"]


def _peaks(path) -> dict[str, np.ndarray]:
    with h5py.File(path, "r") as f:
        return {str(g.attrs["name"]): np.array([np.linalg.norm(g[k][()], axis=-1).max()
                                                for k in ("displacement", "velocity",
                                                          "acceleration")])
                for g in f["probes"].values()}


@pytest.mark.slow
@pytest.mark.mpi
def test_explicit_engine_matches_the_direct_path_on_the_thesis_model(shared_tmp, capsys):
    """Every probe's peak displacement, velocity and acceleration within 1 % of the direct
    path at a tenth of its automatic step (the wheel entering the flexible rail: a
    step-sensitive transient; measured 0.05 / 0.10 / 0.12 %, and 0.03 / 0.07 / 0.09 % against
    the direct path at 2.5e-5 s, whose automatic 5e-4 s is 2.4 / 4.0 / 4.9 % off)."""
    assert run(["transient", str(BASELINE), "--out", str(shared_tmp / "explicit"),
                *SETS, *EXPLICIT]) == 0
    text = capsys.readouterr().out
    assert run(["transient", str(BASELINE), "--out", str(shared_tmp / "direct"),
                *SETS, *DIRECT_DT]) == 0
    if comm.rank == 0:
        assert "central differences (explicit), stable up to" in text
        explicit = _peaks(shared_tmp / "explicit" / "probes.h5")
        direct = _peaks(shared_tmp / "direct" / "probes.h5")
        assert set(explicit) == set(direct)
        rel = np.array([np.abs(explicit[k] / direct[k] - 1) for k in direct])
        assert rel.max() < 0.01, rel.max(axis=0)
        with h5py.File(shared_tmp / "explicit" / "transient.h5", "r") as f:
            assert json.loads(f.attrs["stats"])["engine"] == "explicit"
    comm.Barrier()


def test_a_step_above_the_stable_limit_is_refused(tmp_path, capsys):
    code = run(["transient", str(BASELINE), "--out", str(tmp_path), *SETS, *EXPLICIT,
                "--set", "transient.dt=1e-4"])
    err = capsys.readouterr().err
    assert code == 2
    assert "transient.dt = 0.0001 s: the explicit engine is stable up to" in err
    assert "set by the" in err and "allowed: 0 < transient.dt <=" in err
    assert "Traceback" not in err
    assert not (tmp_path / "transient.h5").exists()


def test_the_explicit_engine_needs_a_lumped_mass(tmp_path, capsys):
    code = run(["transient", str(BASELINE), "--out", str(tmp_path), "--set",
                "transient.engine=explicit"])
    err = capsys.readouterr().err
    assert code == 2 and "needs a diagonal mass: set modal.lumped_mass = true" in err
