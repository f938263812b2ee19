"""The spectral operator on local arrays, split over ranks: each rank builds it on its own
elements in a local node numbering, and a plain sum of the shared nodes' forces (and
masses) over the ranks gives one rank's answer to round-off (the MPI layer's ghost
exchange, which comes with the integration, does the same sum between neighbours only).

Run on 2 ranks with ``mpirun -n 2 ... -m mpi``; on one rank the two parts are summed in
turn (the same local arrays)."""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from spectral_cases import LAM, MU, RHO, distorted_box

from railvib_hpc.fem.spectral_kernel import central_difference_update, spectral_elasticity
from railvib_hpc.fem.spectral_mesh import spectral_mesh

comm = MPI.COMM_WORLD
#: Agreement of the split and the whole (of the largest entry): sums in another order.
RTOL = 1e-13


def _local_operator(sm, elements, lam, mu):
    """The operator of ``elements`` (global node numbers) on their own nodes, numbered
    ``0 .. n_local - 1``; returns it and the local-to-global map."""
    nodes = np.unique(elements)
    local = np.searchsorted(nodes, elements)
    op = spectral_elasticity(sm.order, sm.points[nodes], local, lam, mu, RHO)
    return op, nodes


@pytest.mark.mpi
@pytest.mark.parametrize("order", (2, 4))
def test_elements_split_over_ranks_sum_to_the_whole(order):
    points, hexes = distorted_box(4, amount=0.1)
    # a box block and a distorted block: both kernels on both ranks
    points[np.all(points < 0.5 + 1e-9, axis=1)] = np.round(
        points[np.all(points < 0.5 + 1e-9, axis=1)] * 4) / 4
    sm = spectral_mesh(points, hexes, np.ones(len(hexes), bool), order)
    rng = np.random.default_rng(0)
    lam, mu = rng.uniform(0.5, 1.5, len(hexes)) * LAM, rng.uniform(0.5, 1.5, len(hexes)) * MU
    u = rng.standard_normal((sm.n_nodes, 3))
    whole = spectral_elasticity(order, sm.points, sm.elements, lam, mu, RHO)
    assert len(whole.box_elements) and len(whole.general_elements)
    f_whole = whole.forces(u)
    part = (points[hexes].mean(axis=1)[:, 1] > 0.5).astype(int)      # two slabs along y
    parts = [comm.rank] if comm.size == 2 else [0, 1]
    f = np.zeros_like(u)
    mass = np.zeros(sm.n_nodes)
    for p in parts:
        mine = np.flatnonzero(part == p)
        op, nodes = _local_operator(sm, sm.elements[mine], lam[mine], mu[mine])
        f_local = op.forces(np.ascontiguousarray(u[nodes]))          # local arrays only
        f[nodes] += f_local
        mass[nodes] += op.mass
    if comm.size > 1:
        f = comm.allreduce(f, op=MPI.SUM)
        mass = comm.allreduce(mass, op=MPI.SUM)
    scale = np.abs(f_whole).max()
    assert np.abs(f - f_whole).max() <= RTOL * scale
    assert np.allclose(mass, whole.mass, rtol=RTOL)
    # and one central-difference step of the owned nodes gives the same state
    inv = np.repeat(1.0 / mass[:, None], 3, axis=1)
    u1, v1 = u.copy(), np.zeros_like(u)
    u2, v2 = u.copy(), np.zeros_like(u)
    central_difference_update(u1, v1, f, inv, 1e-5)
    central_difference_update(u2, v2, f_whole.copy(), inv, 1e-5)
    assert np.abs(u1 - u2).max() <= RTOL * np.abs(u2).max()
