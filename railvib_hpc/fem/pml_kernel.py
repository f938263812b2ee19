"""The compiled step of the PML memory terms: one fused loop over the layer's elements
(Numba), the same arithmetic as :meth:`railvib_hpc.fem.pml.PmlElements.advance` in NumPy.

The NumPy step makes a dozen passes over arrays of 72 numbers per element (gradients,
the trapezoidal updates of ``psi``, ``S1`` and ``S2``, two isotropic stresses, the force),
each through main memory; here one element is done at once, its tensors read flat
(``t[24 k + 3 q + l]``) into a few scratch arrays of 72 numbers that stay in the cache,
so the state is read and written once per step. Same formulas, same operation order
where it matters (the trapezoidal updates, the stresses), so the two agree to round-off
(the divisions of the trapezoidal rule are multiplications by the reciprocal here, and the
sums of the two batched products may run in another order). Measured: about 3 times
faster than NumPy on 20,000 to 50,000 elements, one core (``bench/pml_kernel_bench.py``);
what is left is mostly the state's memory traffic (~8 kB per element and step).

State layout (unchanged, so :meth:`~railvib_hpc.fem.pml.PmlElements.memory` and
checkpoints stay compatible): ``t[e, k, q, l]`` (nel, 3, 8, 3) for ``psi``, the previous
gradient ``g``, the previous stress ``sigma``, ``S1`` and ``S2``, updated in place.

Without Numba the module still imports (:data:`NUMBA_AVAILABLE` is False, the functions
are plain Python, far too slow for a run but the same arithmetic, which the tests use)
and :class:`~railvib_hpc.fem.pml.PmlElements` takes its NumPy path.

Examples
--------
>>> import numpy as np
>>> from railvib_hpc.fem.pml_kernel import advance_elements
>>> nel = 2
>>> state = [np.zeros((nel, 3, 8, 3)) for _ in range(5)]      # psi, g, sigma, S1, S2
>>> force = advance_elements(np.zeros((nel, 8, 3)), np.ones((nel, 8, 24)),
...                          np.ones((nel, 8)), np.zeros((nel, 8, 3)), np.ones(nel),
...                          np.ones(nel), 0.0, 1e-3, *state)
>>> force.shape, float(np.abs(force).max())
((2, 8, 3), 0.0)
"""

from __future__ import annotations

import numpy as np

try:
    import numba
except ImportError:                     # the NumPy path of fem.pml is taken instead
    numba = None

#: Whether the compiled kernel is there (Numba importable).
NUMBA_AVAILABLE = numba is not None
#: Nodes and Gauss points (2 x 2 x 2) of the trilinear hexahedron.
NODES = 8
GAUSS_POINTS = 8
#: Space dimension (displacement components, derivatives).
DIM = 3
#: Columns ``c = 3 q + l`` (Gauss point, derivative) of one component of a tensor: an
#: element's tensor ``t[k, q, l]`` is read flat as ``t[COLUMNS k + c]``.
COLUMNS = GAUSS_POINTS * DIM


def _compiled(function):
    """``numba.njit(cache=True)`` of ``function``, or ``function`` itself without Numba
    (the helpers are inlined into :func:`advance_elements` by LLVM: measured as fast as
    Numba's own ``inline="always"``, which doubles the compile time)."""
    if numba is None:
        return function
    return numba.njit(cache=True)(function)


@_compiled
def _element_coefficients(damping, wdet, e, alpha, half, keep, scale, neg_d, sums, products,
                          weights):
    """Per column ``c = 3 q + l`` of element ``e``: the trapezoidal factors of ``psi``
    (``keep = 1 - h (d_l + alpha)``, ``scale = 1 / (1 + h (d_l + alpha))``), ``-d_l``,
    ``p_l`` and ``q_l`` (sum and product of the other two ``d``) and the Gauss weight."""
    for q in range(GAUSS_POINTS):
        d0, d1, d2 = damping[e, q, 0], damping[e, q, 1], damping[e, q, 2]
        total = d0 + d1 + d2
        for l in range(DIM):
            c = DIM * q + l
            d_l = damping[e, q, l]
            hd = half * (d_l + alpha)
            keep[c] = 1.0 - hd
            scale[c] = 1.0 / (1.0 + hd)
            neg_d[c] = -d_l
            sums[c] = total - d_l
            weights[c] = wdet[e, q]
        products[DIM * q] = d1 * d2
        products[DIM * q + 1] = d0 * d2
        products[DIM * q + 2] = d0 * d1


@_compiled
def _element_gradient(ue, grad, e, out):
    """``out[24 k + 3 q + l] = du_k / dx_l`` at the Gauss points of element ``e`` (the sum
    over the nodes outermost: 72 independent sums, the inner loop contiguous)."""
    for k in range(DIM):
        for c in range(COLUMNS):
            acc = 0.0
            for a in range(NODES):
                acc += ue[e, a, k] * grad[e, a, c]
            out[COLUMNS * k + c] = acc


@_compiled
def _advance_psi(psi, g, e, g1, keep, scale, neg_d, half, strain):
    """Trapezoidal ``psi_kl' + (d_l + alpha) psi_kl = g_kl`` of element ``e`` (in place);
    ``strain = -d_l psi_kl``, the memory's part of the stretched strain."""
    for k in range(DIM):
        for c in range(COLUMNS):
            i = COLUMNS * k + c
            value = psi[e, i] * keep[c]
            value += half * (g[e, i] + g1[i])
            value *= scale[c]
            psi[e, i] = value
            strain[i] = neg_d[c] * value


@_compiled
def _isotropic_stress(strain, lam, mu, out):
    """``out = mu (strain + strain^T) + lam tr(strain) I`` at each Gauss point (flat
    ``24 k + 3 q + l``; the order of :func:`railvib_hpc.fem.pml._stress`)."""
    for q in range(GAUSS_POINTS):
        base = DIM * q
        trace = (strain[base] + strain[COLUMNS + base + 1] + strain[2 * COLUMNS + base + 2])
        trace *= lam
        for k in range(DIM):
            for l in range(DIM):
                out[COLUMNS * k + base + l] = (strain[COLUMNS * k + base + l]
                                               + strain[COLUMNS * l + base + k]) * mu
            out[COLUMNS * k + base + k] += trace


@_compiled
def _advance_stress_chain(e, instant, memory, sums, products, weights, keep, scale, half,
                          g, g1, sigma, s1, s2, tw):
    """The new stress ``instant + memory`` and its trapezoidal integrals ``S1' + alpha S1 =
    sigma``, ``S2' + alpha S2 = S1`` of element ``e`` (in place; ``keep = 1 - h alpha``,
    ``scale = 1 / (1 + h alpha)``), the new gradient stored; ``tw[3 c + k]`` = (``memory
    + p_l S1 + q_l S2``, the stress the extra force integrates) times the Gauss weight."""
    for k in range(DIM):
        for c in range(COLUMNS):
            i = COLUMNS * k + c
            new_sigma = instant[i] + memory[i]
            s1_old = s1[e, i]
            s1_new = s1_old * keep
            s1_new += half * (sigma[e, i] + new_sigma)
            s1_new *= scale
            s2_new = s2[e, i] * keep
            s2_new += half * (s1_old + s1_new)
            s2_new *= scale
            s1[e, i] = s1_new
            s2[e, i] = s2_new
            sigma[e, i] = new_sigma
            g[e, i] = g1[i]
            value = memory[i] + sums[c] * s1_new
            value += products[c] * s2_new
            tw[DIM * c + k] = value * weights[c]


@_compiled
def _add_element_force(grad, e, tw, force):
    """``force[e, a, i] = sum_(q, j) dN_a/dx_j tw[(q, j), i]`` (the sum over the columns
    outermost: 24 independent sums)."""
    for a in range(NODES):
        acc0, acc1, acc2 = 0.0, 0.0, 0.0
        for c in range(COLUMNS):
            g_ac = grad[e, a, c]
            acc0 += g_ac * tw[DIM * c]
            acc1 += g_ac * tw[DIM * c + 1]
            acc2 += g_ac * tw[DIM * c + 2]
        force[e, a, 0] = acc0
        force[e, a, 1] = acc1
        force[e, a, 2] = acc2


@_compiled
def advance_elements(ue, grad, wdet, damping, lam, mu, alpha, dt, psi, g, sigma, s1, s2):
    """One step of the PML memory of ``nel`` hexahedra: the state advanced in place to the
    displacements ``ue``, the extra internal force returned.

    Parameters
    ----------
    ue : ndarray, (nel, 8, 3)
        Element displacements at the new step.
    grad : ndarray, (nel, 8, 24)
        ``grad[e, a, 3 q + l] = dN_a / dx_l`` at Gauss point ``q``.
    wdet : ndarray, (nel, 8)
        Gauss weight times Jacobian determinant.
    damping : ndarray, (nel, 8, 3)
        ``d_0, d_1, d_2`` at the Gauss points [1/s].
    lam, mu : ndarray, (nel,)
        Lame parameters [Pa].
    alpha : float
        Frequency shift of the stretching [1/s].
    dt : float
        Time step [s].
    psi, g, sigma, s1, s2 : ndarray, (nel, 3, 8, 3)
        The memory ``t[e, k, q, l]`` (C-contiguous, writable), advanced in place: ``g``
        and ``sigma`` become the new step's gradient and stress.

    Returns
    -------
    ndarray, (nel, 8, 3)
        ``int (T - C : sym(g)) : grad w`` per element and node.
    """
    nel = ue.shape[0]
    size = DIM * COLUMNS
    psi, g, sigma = psi.reshape(nel, size), g.reshape(nel, size), sigma.reshape(nel, size)
    s1, s2 = s1.reshape(nel, size), s2.reshape(nel, size)
    force = np.empty((nel, NODES, DIM))
    half = 0.5 * dt
    keep_s, scale_s = 1.0 - half * alpha, 1.0 / (1.0 + half * alpha)
    keep, scale, neg_d = np.empty(COLUMNS), np.empty(COLUMNS), np.empty(COLUMNS)
    sums, products, weights = np.empty(COLUMNS), np.empty(COLUMNS), np.empty(COLUMNS)
    g1, strain, tw = np.empty(size), np.empty(size), np.empty(size)
    memory, instant = np.empty(size), np.empty(size)
    for e in range(nel):
        _element_coefficients(damping, wdet, e, alpha, half, keep, scale, neg_d, sums,
                              products, weights)
        _element_gradient(ue, grad, e, g1)
        _advance_psi(psi, g, e, g1, keep, scale, neg_d, half, strain)
        _isotropic_stress(strain, lam[e], mu[e], memory)
        _isotropic_stress(g1, lam[e], mu[e], instant)
        _advance_stress_chain(e, instant, memory, sums, products, weights, keep_s, scale_s,
                              half, g, g1, sigma, s1, s2, tw)
        _add_element_force(grad, e, tw, force)
    return force


__all__ = ["NUMBA_AVAILABLE", "advance_elements"]
