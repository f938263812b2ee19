"""``railvib transient`` on a spectral soil on two ranks equals the one-rank run
(``mpirun -n 2 python -m pytest -m mpi``; docs/spectral.md).

The small box of :mod:`spectral_soil_cases` with absorbing faces, springs, Rayleigh damping and
the static start: the elements in two slabs along x, the interface nodes' forces summed
by one ``Allreduce`` per step. The probes differ by the static start's CG tolerance only
(its dot products sum in another order: ~1e-10 relative).
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from spectral_soil_cases import ABSORBING, probes, small_case

from railvib_hpc.log import Reporter
from railvib_hpc.transient.stage import run_transient_stage

comm = MPI.COMM_WORLD
#: The 2-rank run against the 1-rank run: largest difference over the largest value.
TOLERANCE = 1e-7


@pytest.mark.mpi
@pytest.mark.skipif(comm.size != 2, reason="two ranks")
def test_two_ranks_equal_one_rank(shared_tmp):
    case = small_case(*ABSORBING, "damping.model=rayleigh")
    two = run_transient_stage(case, shared_tmp / "two", comm, Reporter(comm.rank))
    verdict = None
    if comm.rank == 0:
        one = run_transient_stage(case, shared_tmp / "one", MPI.COMM_SELF, Reporter(0))
        a, b = probes(shared_tmp / "one"), probes(shared_tmp / "two")
        worst = max(float(np.abs(a[k][q] - b[k][q]).max() / np.abs(a[k][q]).max())
                    for k in a for q in ("displacement", "velocity"))
        print(f"\n2 ranks against 1: largest relative difference {worst:.2e} "
              f"({two['n_dofs']:,} DOFs, {two['n_steps']} steps)")
        # (the step from the power iteration: equal to its round-off)
        verdict = (one["n_dofs"] == two["n_dofs"] and one["n_steps"] == two["n_steps"]
                   and abs(one["dt"] / two["dt"] - 1.0) < 1e-9 and worst < TOLERANCE,
                   worst, one["dt"], two["dt"])
    verdict = comm.bcast(verdict, root=0)
    assert verdict[0], verdict
