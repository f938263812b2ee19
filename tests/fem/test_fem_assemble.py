"""Serial assembly and DOF elimination."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from railvib_hpc.fem import assemble_matrix, assemble_vector, element_dofs, eliminate_dofs


def test_element_dofs_node_major_and_offsets():
    conn = np.array([[0, 2], [2, 1]])
    assert element_dofs(conn, 3).tolist() == [[0, 1, 2, 6, 7, 8], [6, 7, 8, 3, 4, 5]]
    offset = np.array([0, 3, 9])              # node 1 has 6 DOFs (beam), others 3
    assert element_dofs(conn, 3, offset).tolist() == [[0, 1, 2, 9, 10, 11],
                                                      [9, 10, 11, 3, 4, 5]]


def test_assemble_matches_loop_reference():
    rng = np.random.default_rng(0)
    nel, n, ndof = 30, 6, 25
    dofs = np.stack([rng.choice(ndof, n, replace=False) for _ in range(nel)])
    ke = rng.normal(size=(nel, n, n))
    ref = np.zeros((ndof, ndof))
    for e in range(nel):                       # reference: plain loop over elements
        ref[np.ix_(dofs[e], dofs[e])] += ke[e]
    K = assemble_matrix(dofs, ke, ndof)
    assert K.format == "csr"
    assert np.allclose(K.toarray(), ref, rtol=0, atol=1e-13)
    fe = rng.normal(size=(nel, n))
    ref_v = np.zeros(ndof)
    np.add.at(ref_v, dofs, fe)
    assert np.allclose(assemble_vector(dofs, fe, ndof), ref_v, rtol=0, atol=1e-13)


def test_eliminate_dofs():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    K, M = A + A.T, A @ A.T
    Kr, Mr, free = eliminate_dofs(sp.csr_matrix(K), sp.csr_matrix(M), [4, 1, 4])
    assert free.tolist() == [0, 2, 3, 5]
    assert np.array_equal(Kr.toarray(), K[np.ix_(free, free)])
    assert np.array_equal(Mr.toarray(), M[np.ix_(free, free)])
    mask = np.zeros(6, dtype=bool)
    mask[[1, 4]] = True
    Kr2, none, free2 = eliminate_dofs(sp.csr_matrix(K), None, mask)
    assert none is None and free2.tolist() == free.tolist()
    assert np.array_equal(Kr2.toarray(), Kr.toarray())
