"""Perfectly matched layer (PML) for elastodynamics in the time domain: the profile and the
batched memory kernel of the stretched hexahedra (NumPy, or the fused Numba loop of
:mod:`railvib_hpc.fem.pml_kernel` where Numba is installed).

Formulation: the unsplit, displacement-based PML with complex coordinate stretching
``x_j -> x~_j``, ``dx~_j / dx_j = lambda_j(x_j) = 1 + d_j(x_j) r``, ``r = 1 / (s +
alpha)`` (``s = i omega``; the frequency-shifted stretching of Kuzuoglu & Mittra 1996;
``alpha = 0`` is the classical one of Basu & Chopra 2003, 2004 and Basu 2009 for explicit
3-D FE), written with memory variables at the Gauss points. Multiplying the stretched
momentum balance by ``J = lambda_0 lambda_1 lambda_2`` gives the weak form

    int rho J s^2 u . w dV + sum_ij int (J / lambda_j) sigma_ij dw_i/dx_j dV = 0,
    sigma = C : sym(G~),   G~_kl = (1 / lambda_l) du_k / dx_l.

With ``e1 = sum d``, ``e2 = d0 d1 + d1 d2 + d0 d2``, ``e3 = d0 d1 d2`` and, per column
``j``, ``p_j = sum_{a != j} d_a``, ``q_j = prod_{a != j} d_a``::

    mass side:  s^2 J = s^2 + e1 (s - alpha + alpha^2 r) + e2 (1 - 2 alpha r + alpha^2 r^2)
                        + e3 (r - 2 alpha r^2 + alpha^2 r^3)      (lumped diagonals of e_k
                                                                   at the Gauss points, chains
                                                                   chi_k = r^k u at the nodes)
    stiffness:  T_ij = sigma_ij + p_j S1_ij + q_j S2_ij,  S1 = r sigma, S2 = r S1
    strain:     G~_kl = g_kl - d_l psi_kl,   psi_kl' + (d_l + alpha) psi_kl = g_kl.

Outside the layer ``d = 0`` and every extra term vanishes, so the layer needs no interface
condition and the soil's layering continues through it. Why this form: it is
displacement-only (no stress DOFs, so the explicit engine's lumped diagonal mass and its
O(N) step stay), it is unsplit (the memory lives at the Gauss points of the layer's
elements only), the stretching is stable for isotropic solids, layered or not (Becache,
Fauqueux & Joly 2003 find PML instabilities for some anisotropic media only), and its
attenuation does not depend on the incidence angle, so it also absorbs the Rayleigh waves
that run into the side layers. The frequency shift keeps every memory variable bounded
under a static or slowly varying stress (with ``alpha = 0``, ``S1`` of a constant stress
grows linearly; measured: energy trapped between roller faces grew after ~7 s). The
layer's elements must use the plain full-integration stiffness in K (the gradients the
memory terms use): with B-bar in K the layer is unstable (measured, module
:mod:`railvib_hpc.transient.pml`).

Time discretisation (central differences of the explicit engine; the step ``t_n ->
t_{n+1}`` has ``u_{n+1}`` before any force is needed): every memory ODE by the trapezoidal
rule (unconditionally stable), ``M_e1`` at the full-step velocity (a diagonal, like the
face dashpots), so nothing is factored and the step is not limited by the layer's damping.

Profile (Collino & Tsogka 2001): ``d(xi) = d_max (xi / L)^p`` with ``xi`` the depth into a
layer of thickness ``L`` and ``d_max = (p + 1) c_P ln(1 / R) / (2 L)`` for a target
reflection ``R`` of a plane P wave at normal incidence in the continuum (a fixed face
behind the layer). The discrete layer reflects more the fewer elements it has across:
``d_max h / c_P = (p + 1) ln(1 / R) / (2 n)`` for ``n`` elements of size ``h``.

Examples
--------
>>> import numpy as np
>>> from railvib_hpc.fem.pml import PmlElements, profile_strength
>>> round(profile_strength(300.0, 5.0, 2, 1e-4), 3)       # 3 c ln(1e4) / (2 L)
828.931
>>> x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
...               [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)[None]
>>> layer = PmlElements(x, lam=1e8, mu=5e7, damping=np.zeros((1, 8, 3)))
>>> u = np.random.default_rng(0).normal(size=(1, 8, 3))
>>> _ = layer.start(u)
>>> bool(np.abs(layer.advance(u, 1e-3)).max() == 0.0)    # d = 0: no extra force
True
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .hex8 import hex8_jacobians
from .pml_kernel import NUMBA_AVAILABLE, advance_elements
from .reference import GAUSS_VALUES

#: Default profile exponent (quadratic: Collino & Tsogka 2001 found p = 2 to 3 best).
DEFAULT_POWER = 2
#: Default target reflection coefficient of the continuous layer at normal incidence.
DEFAULT_REFLECTION = 1e-4
#: Fewest element layers across a PML below which its discrete reflection is far above
#: the target (Collino & Tsogka 2001: 5 to 10 points per layer for R ~ 1e-3 to 1e-4).
MIN_ELEMENTS = 5
#: Numbers of memory per Gauss point: psi (9), the previous gradient (9), the previous
#: stress, S1 and S2 (9 each, kept as full 3 x 3 for the batched products).
STATE_PER_POINT = 45
#: The implementation of :meth:`PmlElements.advance` new kernels take: ``"numba"`` (the
#: fused loop of :mod:`~railvib_hpc.fem.pml_kernel`, several times faster) where Numba
#: imports, ``"numpy"`` (the batched array operations) otherwise.
DEFAULT_KERNEL = "numba" if NUMBA_AVAILABLE else "numpy"
#: The implementations of :meth:`PmlElements.advance`.
KERNELS = ("numba", "numpy")


def profile_strength(c_p: float, thickness: float, power: float, reflection: float) -> float:
    """``d_max = (p + 1) c_P ln(1 / R) / (2 L)`` [1/s] (Collino & Tsogka 2001).

    Parameters
    ----------
    c_p
        Largest P-wave speed in the layer [m/s].
    thickness
        Layer thickness ``L`` [m].
    power
        Profile exponent ``p``.
    reflection
        Target reflection ``R`` of the continuous layer at normal incidence (0 < R < 1).
    """
    return (power + 1.0) * c_p * np.log(1.0 / reflection) / (2.0 * thickness)


def profile(depth: ArrayLike, thickness: float, d_max: float, power: float) -> np.ndarray:
    """``d = d_max (xi / L)^p`` for depths ``xi`` into the layer (0 outside it).

    >>> profile([-1.0, 0.0, 2.5, 5.0, 6.0], 5.0, 100.0, 2).tolist()
    [0.0, 0.0, 25.0, 100.0, 100.0]
    """
    xi = np.clip(np.asarray(depth, dtype=float) / thickness, 0.0, 1.0)
    return d_max * xi ** power


def mass_coefficients(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``e1 = sum d``, ``e2 = d0 d1 + d1 d2 + d0 d2``, ``e3 = d0 d1 d2`` of ``d`` (..., 3)."""
    d0, d1, d2 = d[..., 0], d[..., 1], d[..., 2]
    return d0 + d1 + d2, d0 * d1 + d1 * d2 + d0 * d2, d0 * d1 * d2


def lumped_mass_coefficients(x: ArrayLike, rho: ArrayLike, damping: ArrayLike
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The row-sum lumped masses ``int rho e_k N_a dV`` (``k = 1, 2, 3``) of hexahedra at
    their nodes, (nel, 8) each, with ``e_k`` (:func:`mass_coefficients`) of ``damping``
    (``d_0, d_1, d_2`` at the 2x2x2 Gauss points, (nel, 8, 3)): the mass side of the
    stretched weak form at the same Gauss points as the stiffness side's memory terms.

    Why the Gauss points and not the nodes: for a mode with the layer's mass weighted by an
    average ``d_m`` of the profile and its stiffness by ``d_k``, ``m s^2 (1 + d_m r) + k (1 +
    d_k r) = 0`` (``r = 1 / (s + alpha)``) is the cubic ``m s^3 + m (alpha + d_m) s^2 + k s
    + k (alpha + d_k) = 0``, stable (Routh-Hurwitz) only while ``d_m >= d_k``. ``d`` taken at
    the nodes gives ``d_m = 0`` at the layer's inner nodes, where the memory terms' Gauss
    points have ``d > 0``: the semi-discrete layer grew (measured, a box with a one-element
    layer: growth rate +25 1/s with ``d`` at the nodes, every mode decaying with it at the
    Gauss points; the coarse thesis model's y-face layers grew at ~20 1/s).

    >>> import numpy as np
    >>> x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
    ...               [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)[None]
    >>> m1, m2, m3 = lumped_mass_coefficients(x, 2000.0, np.full((1, 8, 3), 10.0))
    >>> [round(float(m.sum()), 6) for m in (m1, m2, m3)]    # rho V e_k: e = 30, 300, 1000
    [60000.0, 600000.0, 2000000.0]
    """
    _, wdet = hex8_jacobians(x)                          # (nel, q)
    weight = np.asarray(rho, dtype=float).reshape(-1, 1) * wdet
    return tuple(np.einsum("eq,qa->ea", weight * c, GAUSS_VALUES)
                 for c in mass_coefficients(np.asarray(damping, dtype=float)))


def _stress(g: np.ndarray, lam: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Isotropic stress of the symmetric part of gradients ``g[e, k, q, l] = du_k / dx_l``
    at Gauss point ``q``, in the same layout (nel, 3, 8, 3)."""
    out = g + g.transpose(0, 3, 2, 1)
    out *= mu[:, None, None, None]                   # 2 mu eps
    tr = np.einsum("ekqk->eq", g) * lam[:, None]
    for k in range(3):
        out[:, k, :, k] += tr
    return out


class PmlElements:
    """The memory terms of the PML on a batch of hexahedra (module notes).

    The elements' instantaneous stiffness ``C : sym(grad u)`` is the ordinary one, in the
    assembled K; :meth:`advance` returns the rest of the stretched internal force:
    ``int (T - C : sym(g)) : grad w``. Memory: :data:`STATE_PER_POINT` numbers per Gauss
    point plus the gradients (192 per element): ~3.7 kB per element, in the layer only.
    Work: the gradients and the forces are two batched (8 x 24) products per element; the
    tensors are kept as ``t[e, k, q, l]`` (component, Gauss point, derivative) so that
    both are plain ``matmul``.

    Parameters
    ----------
    x
        Node coordinates (nel, 8, 3).
    lam, mu
        Lame parameters [Pa], per element or scalar.
    damping
        ``d_0, d_1, d_2`` at the 2x2x2 Gauss points, (nel, 8, 3) [1/s].
    alpha
        The frequency shift ``alpha`` [1/s] of the stretching ``1 + d / (s + alpha)``
        (0: the classical ``1 + d / s``).

    Attributes
    ----------
    kernel : str
        How :meth:`advance` computes, one of :data:`KERNELS` (default
        :data:`DEFAULT_KERNEL`; for the log): both give the same state and force to
        round-off, so it may be switched between steps.
    """

    kernel: str = DEFAULT_KERNEL

    def __init__(self, x: ArrayLike, lam: ArrayLike, mu: ArrayLike, damping: ArrayLike,
                 alpha: float = 0.0):
        x = np.asarray(x, dtype=float)
        nel = x.shape[0]
        grad, wdet = hex8_jacobians(x)                  # (nel, q, a, l), (nel, q)
        # G[e, a, (q, l)] = dN_a / dx_l at Gauss point q
        self.grad = np.ascontiguousarray(grad.transpose(0, 2, 1, 3).reshape(nel, 8, 24))
        self.wdet = wdet[:, None, :, None]
        self.lam = np.broadcast_to(np.asarray(lam, dtype=float), (nel,)).copy()
        self.mu = np.broadcast_to(np.asarray(mu, dtype=float), (nel,)).copy()
        d = np.asarray(damping, dtype=float)
        # per column l (the last axis): d_l, p_l = sum of the other two, q_l = their product
        self.d = d[:, None, :, :]
        self.p = (d.sum(axis=-1, keepdims=True) - d)[:, None, :, :]
        self.q = np.stack([d[..., 1] * d[..., 2], d[..., 0] * d[..., 2],
                           d[..., 0] * d[..., 1]], axis=-1)[:, None, :, :]
        self.alpha = float(alpha)
        shape = (nel, 3, 8, 3)
        self.psi, self.g = np.zeros(shape), np.zeros(shape)
        self.sigma, self.s1, self.s2 = np.zeros(shape), np.zeros(shape), np.zeros(shape)

    @property
    def nbytes(self) -> int:
        """Memory of the kernel's arrays [bytes]."""
        return sum(a.nbytes for a in (self.grad, self.wdet, self.d, self.p, self.q, self.psi,
                                      self.g, self.sigma, self.s1, self.s2))

    def gradients(self, ue: np.ndarray) -> np.ndarray:
        """``g[e, k, q, l] = du_k / dx_l`` at the Gauss points of element displacements
        ``ue`` (nel, 8, 3)."""
        g = np.matmul(ue.transpose(0, 2, 1), self.grad)          # (nel, 3, 24)
        return g.reshape(-1, 3, 8, 3)

    def _force(self, t: np.ndarray) -> np.ndarray:
        """``f[e, a, i] = sum_q wdet sum_j dN_a/dx_j t[e, i, q, j]`` (nel, 8, 3)."""
        tw = (t * self.wdet).reshape(-1, 3, 24)
        return np.matmul(self.grad, tw.transpose(0, 2, 1))

    def start(self, ue: np.ndarray) -> np.ndarray:
        """Set the state at ``t_0`` (memory at rest) from the displacements ``ue``; the
        extra force then is zero (returned, (nel, 8, 3))."""
        self.g = self.gradients(ue)
        for a in (self.psi, self.s1, self.s2):
            a[...] = 0.0
        self.sigma = _stress(self.g, self.lam, self.mu)
        return np.zeros_like(ue)

    def subset(self, sel) -> PmlElements:
        """The elements ``sel`` (an index or a slice) as a kernel of their own, its memory at
        rest."""
        out = object.__new__(PmlElements)
        out.grad, out.wdet = self.grad[sel], self.wdet[sel]
        out.lam, out.mu = self.lam[sel], self.mu[sel]
        out.d, out.p, out.q, out.alpha = self.d[sel], self.p[sel], self.q[sel], self.alpha
        out.kernel = self.kernel
        shape = (len(out.lam), 3, 8, 3)
        out.psi, out.g = np.zeros(shape), np.zeros(shape)
        out.sigma, out.s1, out.s2 = np.zeros(shape), np.zeros(shape), np.zeros(shape)
        return out

    def memory(self) -> tuple[np.ndarray, ...]:
        """A copy of the memory (for :meth:`restore`)."""
        return tuple(a.copy() for a in (self.psi, self.g, self.sigma, self.s1, self.s2))

    def restore(self, memory: tuple[np.ndarray, ...]) -> None:
        """Set the memory of :meth:`memory` back (takes its arrays: use it once)."""
        self.psi, self.g, self.sigma, self.s1, self.s2 = memory

    def instant_matrices(self, dt: float) -> np.ndarray:
        """``d f / d u_{n+1}`` of :meth:`advance`, per element (nel, 24, 24), DOFs ordered
        (node, component): the part of the extra force that the next step's
        displacements make through the trapezoidal memory updates (the rest depends on
        the history only, so ``advance(u) = A u + advance(0)``). For an implicit step
        (the direct engine): ``A`` goes into the effective matrix.

        ``A`` is symmetric: with ``h = dt / 2``, the trapezoidal ``psi`` makes the
        step's stretched strain ``(1 - c_l d_l) g_kl``, ``c_l = h / (1 + h (d_l +
        alpha))``, and the chains ``S1, S2`` multiply column ``j`` of the stress by ``1 +
        w p_j + w^2 q_j = prod_{a != j} (1 + w d_a)``, ``w = h / (1 + h alpha)``, so
        ``K + A`` has the element form ``f_j C_ijkl f'_l`` with ``f_j / (1 - c_j d_j) =
        prod_a (1 + h (alpha + d_a)) / (1 + h alpha)^3`` the same for every ``j``
        (the discrete ``J / (lambda_j lambda_l)``): symmetric, and positive where C is.

        >>> import numpy as np
        >>> x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
        ...               [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)[None]
        >>> layer = PmlElements(x, 1e8, 5e7, np.full((1, 8, 3), 300.0), alpha=20.0)
        >>> rng = np.random.default_rng(1)
        >>> A = layer.instant_matrices(1e-4)
        >>> _ = layer.start(rng.normal(size=(1, 8, 3)))          # some history
        >>> _ = layer.advance(rng.normal(size=(1, 8, 3)), 1e-4)
        >>> saved = layer.memory()
        >>> f0 = layer.advance(np.zeros((1, 8, 3)), 1e-4)      # the history's part
        >>> layer.restore(saved)
        >>> u = rng.normal(size=(1, 8, 3))
        >>> f = layer.advance(u, 1e-4)
        >>> bool(np.allclose(f.ravel(), A[0] @ u.ravel() + f0.ravel(), rtol=1e-12,
        ...                  atol=1e-12 * np.abs(f).max()))
        True
        >>> bool(np.abs(A[0] - A[0].T).max() < 1e-13 * np.abs(A[0]).max())
        True
        """
        nel = len(self.lam)
        out = np.empty((nel, 24, 24))
        for j in range(24):            # the element's 24 unit displacements, all at once
            probe = self.subset(slice(None))
            ue = np.zeros((nel, 8, 3))
            ue[:, j // 3, j % 3] = 1.0
            out[:, :, j] = probe.advance(ue, dt).reshape(nel, 24)
        return out

    def advance(self, ue: np.ndarray, dt: float) -> np.ndarray:
        """Advance the memory to the next step's displacements ``ue`` (nel, 8, 3) and
        return the extra internal force there, (nel, 8, 3). Call once per step.

        Computed by :attr:`kernel`: the fused Numba loop or the NumPy arrays."""
        if self.kernel == "numba":
            return self._advance_numba(ue, dt)
        if self.kernel != "numpy":
            raise ValueError(f"PmlElements.kernel {self.kernel!r} is not one of {KERNELS}")
        return self._advance_numpy(ue, dt)

    def _advance_numba(self, ue: np.ndarray, dt: float) -> np.ndarray:
        """:meth:`advance` by :func:`~railvib_hpc.fem.pml_kernel.advance_elements` (the
        state in place, made C-contiguous and writable first where it is not)."""
        if not NUMBA_AVAILABLE:
            raise ImportError("PmlElements.kernel 'numba' needs numba (pip install numba); "
                              "'numpy' needs nothing")
        state = [np.require(a, dtype=float, requirements=("C", "W"))
                 for a in (self.psi, self.g, self.sigma, self.s1, self.s2)]
        self.psi, self.g, self.sigma, self.s1, self.s2 = state
        inputs = [np.ascontiguousarray(a, dtype=float) for a in
                  (ue, self.grad, self.wdet[:, 0, :, 0], self.d[:, 0], self.lam, self.mu)]
        return advance_elements(*inputs, self.alpha, float(dt), *state)

    def _advance_numpy(self, ue: np.ndarray, dt: float) -> np.ndarray:
        """:meth:`advance` by batched NumPy operations (the reference implementation)."""
        g1 = self.gradients(ue)
        half = 0.5 * dt
        hd = half * (self.d + self.alpha)
        psi = self.psi
        psi *= 1.0 - hd
        psi += half * (self.g + g1)
        psi /= 1.0 + hd                  # trapezoidal: psi' + (d_l + alpha) psi = g
        memory = _stress(-self.d * psi, self.lam, self.mu)   # C : sym(-d_l psi_kl)
        sigma = _stress(g1, self.lam, self.mu)
        sigma += memory
        s1_old = self.s1.copy()
        a = half * self.alpha
        self.s1 *= 1.0 - a
        self.s1 += half * (self.sigma + sigma)
        self.s1 /= 1.0 + a               # S1' + alpha S1 = sigma, S2' + alpha S2 = S1
        self.s2 *= 1.0 - a
        self.s2 += half * (s1_old + self.s1)
        self.s2 /= 1.0 + a
        memory += self.p * self.s1
        memory += self.q * self.s2
        self.g, self.sigma = g1, sigma
        return self._force(memory)


__all__ = ["DEFAULT_KERNEL", "DEFAULT_POWER", "DEFAULT_REFLECTION", "KERNELS", "MIN_ELEMENTS",
           "PmlElements", "lumped_mass_coefficients", "mass_coefficients", "profile",
           "profile_strength"]
