"""Directional spring-dampers (COMBIN14 KEYOPT(2) = 1, 2, 3)."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.fem import assemble_matrix, damper_matrices, spring_dofs, spring_matrices


@pytest.mark.parametrize("direction", [0, 1, 2])
def test_spring_acts_on_exactly_one_dof_pair(direction):
    # node 0: solid (3 DOFs), node 1: beam (6 DOFs) -> first-DOF offsets 0 and 3
    offset = np.array([0, 3])
    k = 7.0e9
    ke = spring_matrices(k, direction)
    assert ke.shape == (1, 2, 2)
    dofs = spring_dofs([[0, 1]], direction, offset)
    assert dofs.tolist() == [[direction, 3 + direction]]
    K = assemble_matrix(dofs, ke, 9).toarray()
    expected = np.zeros((9, 9))
    a, b = direction, 3 + direction
    expected[a, a] = expected[b, b] = k
    expected[a, b] = expected[b, a] = -k
    assert np.array_equal(K, expected)
    # a unit relative displacement along the spring gives the force k, anything else 0
    u = np.zeros(9)
    u[b] = 1.0
    assert (K @ u)[[a, b]].tolist() == [-k, k]
    u = np.ones(9)
    u[b] = 0.0
    u[a] = 0.0
    assert not np.any(K @ u)


def test_batched_springs_and_dampers():
    k = np.array([1.0, 2.0, 3.0])
    d = np.array([2, 0, 1])
    ke = spring_matrices(k, d)
    assert np.array_equal(ke[:, 0, 0], k) and np.array_equal(ke[:, 0, 1], -k)
    assert np.array_equal(damper_matrices(5e5, d), np.broadcast_to(5e5 * ke[0] / k[0], (3, 2, 2)))
    nodes = np.array([[0, 1], [1, 2], [2, 0]])
    dofs = spring_dofs(nodes, d, 3 * np.arange(3))
    assert dofs.tolist() == [[2, 5], [3, 6], [7, 1]]
    with pytest.raises(ValueError):
        spring_matrices(k, 3)
    with pytest.raises(ValueError):
        spring_dofs(nodes, 1.0, np.arange(3))
