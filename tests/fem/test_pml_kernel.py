"""The compiled PML memory step (:mod:`railvib_hpc.fem.pml_kernel`) against the NumPy one
(:meth:`railvib_hpc.fem.pml.PmlElements.advance` with ``kernel = "numpy"``): the same force
and state to round-off on distorted hexahedra with random damping profiles, over several
steps and through ``start``, ``memory``/``restore``, ``subset`` and ``instant_matrices``."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.fem.pml import PmlElements

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parents[2]

#: Relative agreement of the two kernels (of each array's largest entry).
RTOL = 1e-12
#: Elements of the random batch.
N_ELEMENTS = 40
#: Unit cube's nodes in the hexahedron's order.
CUBE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                 [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
#: Step [s]: with d up to 900 1/s, d dt / 2 up to 0.45 (the memory decays strongly).
DT = 1e-3


def _pair(seed: int = 0) -> tuple[PmlElements, PmlElements]:
    """Two equal kernels on random distorted elements, one per implementation."""
    rng = np.random.default_rng(seed)
    x = 2.0 * CUBE[None] + rng.uniform(-0.3, 0.3, (N_ELEMENTS, 8, 3))
    x += rng.uniform(-50.0, 50.0, (N_ELEMENTS, 1, 3))
    lam, mu = rng.uniform(5e7, 2e8, N_ELEMENTS), rng.uniform(2e7, 1e8, N_ELEMENTS)
    damping = rng.uniform(0.0, 900.0, (N_ELEMENTS, 8, 3))
    damping[rng.random((N_ELEMENTS, 8, 3)) < 0.3] = 0.0       # outside some faces
    numba_layer = PmlElements(x, lam, mu, damping, alpha=25.0)
    numpy_layer = PmlElements(x, lam, mu, damping, alpha=25.0)
    numba_layer.kernel, numpy_layer.kernel = "numba", "numpy"
    return numba_layer, numpy_layer


def _assert_close(a: np.ndarray, b: np.ndarray) -> None:
    scale = max(np.abs(b).max(), np.finfo(float).tiny)
    assert np.abs(a - b).max() <= RTOL * scale


def _assert_same_state(fast: PmlElements, ref: PmlElements) -> None:
    for a, b in zip(fast.memory(), ref.memory(), strict=True):
        _assert_close(a, b)


def _step_both(fast, ref, u):
    f_fast, f_ref = fast.advance(u, DT), ref.advance(u, DT)
    assert f_fast.shape == f_ref.shape == u.shape
    _assert_close(f_fast, f_ref)
    _assert_same_state(fast, ref)
    return f_fast


def test_the_numba_step_equals_the_numpy_step_over_several_steps():
    fast, ref = _pair()
    rng = np.random.default_rng(1)
    u = 1e-3 * rng.normal(size=(N_ELEMENTS, 8, 3))
    fast.start(u)
    ref.start(u)
    for _ in range(6):
        u = u + 1e-4 * rng.normal(size=u.shape)
        force = _step_both(fast, ref, u)
    assert np.abs(force).max() > 0.0


def test_the_numba_step_equals_the_numpy_step_through_memory_and_restore():
    fast, ref = _pair(2)
    rng = np.random.default_rng(3)
    u = 1e-3 * rng.normal(size=(N_ELEMENTS, 8, 3))
    fast.start(u)
    ref.start(u)
    for _ in range(3):
        _step_both(fast, ref, u + 1e-4 * rng.normal(size=u.shape))
    saved_fast, saved_ref = fast.memory(), ref.memory()
    _step_both(fast, ref, np.zeros_like(u))                    # the history's part
    fast.restore(saved_fast)
    ref.restore(saved_ref)
    _assert_same_state(fast, ref)
    for _ in range(3):
        _step_both(fast, ref, u + 1e-4 * rng.normal(size=u.shape))
    # a restored state in another layout (a strided view) is taken as well
    fast.restore(tuple(np.asfortranarray(a) for a in fast.memory()))
    _step_both(fast, ref, u)


def test_the_numba_subsets_and_instant_matrices_equal_the_numpy_ones():
    fast, ref = _pair(4)
    _assert_close(fast.instant_matrices(DT), ref.instant_matrices(DT))
    rng = np.random.default_rng(5)
    every_other = slice(None, None, 2)                        # strided views of the inputs
    sub_fast, sub_ref = fast.subset(every_other), ref.subset(every_other)
    assert (sub_fast.kernel, sub_ref.kernel) == ("numba", "numpy")
    u = rng.normal(size=(len(sub_ref.lam), 8, 3))
    sub_fast.start(u)
    sub_ref.start(u)
    for _ in range(3):
        _step_both(sub_fast, sub_ref, u + 0.1 * rng.normal(size=u.shape))


def test_an_unknown_kernel_is_refused():
    layer = _pair()[1]
    layer.kernel = "fortran"
    with pytest.raises(ValueError, match="fortran"):
        layer.advance(np.zeros((N_ELEMENTS, 8, 3)), DT)


def test_without_numba_the_numpy_path_is_taken_and_the_plain_kernel_agrees():
    """Numba blocked in a fresh interpreter: the package imports, new kernels take NumPy, and
    the kernel's Python source (the same arithmetic, uncompiled) gives the NumPy force."""
    script = textwrap.dedent("""
        import sys
        sys.modules["numba"] = None                       # import numba -> ImportError
        import numpy as np
        from railvib_hpc.fem import pml, pml_kernel
        assert not pml_kernel.NUMBA_AVAILABLE and pml.DEFAULT_KERNEL == "numpy"
        rng = np.random.default_rng(0)
        x = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                      [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], float)
        x = x[None] + rng.uniform(-0.2, 0.2, (2, 8, 3))
        layer = pml.PmlElements(x, 1e8, 5e7, rng.uniform(0, 500, (2, 8, 3)), alpha=20.0)
        assert layer.kernel == "numpy"
        u = rng.normal(size=(2, 8, 3))
        layer.start(u)
        state = [a.copy() for a in layer.memory()]
        f_ref = layer.advance(2 * u, 1e-3)
        f = pml_kernel.advance_elements(2 * u, layer.grad, layer.wdet[:, 0, :, 0],
                                        layer.d[:, 0], layer.lam, layer.mu, 20.0, 1e-3, *state)
        assert np.abs(f - f_ref).max() <= 1e-12 * np.abs(f_ref).max()
        layer.kernel = "numba"
        try:
            layer.advance(u, 1e-3)
        except ImportError as err:
            assert "needs numba" in str(err)
        else:
            raise AssertionError("the numba kernel ran without numba")
        print("ok")
    """)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                         env=env, cwd=ROOT, timeout=120)
    assert run.returncode == 0 and run.stdout.strip() == "ok", run.stderr
