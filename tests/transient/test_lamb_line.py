"""Lamb's problem at ten wavelengths for the O(N) engines (issue 28, item 7).

A vertical line load on an elastic half-space (plane strain, Lamb 1904; the closed-form
Cagniard-de Hoop kernel of :mod:`lamb`, ``nu = 1/4``): a 3-D quarter model at ten wavelengths
would hold some 10^7 DOFs, the plane-strain slab 0.5 M. The slab is one element of 1 m
thick, ``uy`` fixed on both faces (the default rollers), so every section carries the same
``ux, uz``: the plane-strain solution of the same hexahedra, whose dispersion is the 3-D
grid's for waves in the x-z plane (:mod:`railvib_hpc.fem.dispersion`). Half of it
(``x >= 0``, roller on the symmetry plane), the load ``sin^4`` of duration ``T`` on the
line ``x = z = 0``.

Wavelength: the Rayleigh pulse of the vertical velocity is the Hilbert transform of
``s'``, whose amplitude spectrum ``f |S(f)|`` peaks at ``f_v = 1.094 / T``;
``lambda_R = c_R / f_v`` (the S wavelength is 1.088 times longer). Receivers on the surface
at 2, 5 and 11 ``lambda_R`` (the last 10.1 S wavelengths).

Elements per wavelength: 24 per ``lambda_R`` (22 per S wavelength at ``f_v``), chosen with
:func:`railvib_hpc.fem.dispersion.propagate`: the exact Rayleigh velocity pulse carried 11
wavelengths along the grid axis by the S relation at the Rayleigh wavelength (the mesh
check's proxy, :mod:`railvib_hpc.mesh.dispersion_check`), lumped mass, central differences
at the engine's step, predicts a peak-velocity error of -0.4 % at 20, -2.6 % at 24 and
-1.1 % at 28 per wavelength over 10 wavelengths. The mesh check's own harmonic bound at
``f_v`` (worst direction) is 3.0 % at 24; at the top of the pulse's band (1 % of the
spectrum, 3.4 ``f_v``) no mesh of this size resolves it, so that bound (100 %) is not
what a broadband pulse sees.

The step: 0.9 of the grid's critical Courant number
(:func:`~railvib_hpc.fem.dispersion.critical_courant`, 1 for this element), what the
engines' automatic step is on it (:func:`~railvib_hpc.transient.explicit.stability_limit`
gives the same 0.900 on this mesh, in 80 s of Krylov-Schur: not repeated here).

The far faces are rollers and the base fixed, far enough that no reflection reaches a
receiver before its window closes (``x_max`` 18.2, base 11.5 wavelengths; absorbing faces
would shorten it, but their explicit dashpots halve the explicit engine's step on a soil
model: :func:`~railvib_hpc.transient.explicit.stability_limit`, tests/transient/test_explicit.py).

Measured (1 rank; 482,448 DOFs, 663 steps, 11.5 s explicit, 17.4 s IMEX): peak velocity of the
Rayleigh pulse +1.7, +2.1, -2.1 % (explicit) and +1.8, +2.4, -2.7 % (IMEX, the first
wavelength around the load implicit) at 2, 5, 11 wavelengths. The displacement's peak is
more sensitive to the dispersion (+3, +7, +14 %): the criterion is the peak velocity
(issue 28, item 2).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from lamb import GAMMA, lamb_line_response, pulse, rayleigh_residue, rayleigh_slowness
from mpi4py import MPI
from wave_cases import RHO, box_mesh, soil_case

comm = MPI.COMM_WORLD
NU = 0.25
#: ``f_v T`` of the sin^4 pulse: the peak of ``f |S(f)|`` (FFT, computed in a test).
F_PEAK_T = 1.09375
#: Elements per Rayleigh wavelength at ``f_v`` (module notes).
EPW = 24
#: Receivers [Rayleigh wavelengths]; the domain [wavelengths]: x_max, depth.
RECEIVERS = (2.0, 5.0, 11.0)
X_MAX, DEPTH = 18.2, 11.5
#: Fraction of the critical Courant number (the engines' ``STEP_SAFETY``).
COURANT = 0.9
#: Line load [N/m].
FORCE = 1e5


# --------------------------------------------------------------------------- the reference
def test_rayleigh_slowness_and_the_pulse_peak_frequency():
    assert rayleigh_slowness(NU) == pytest.approx(GAMMA, rel=1e-12)     # Pekeris's c_S / c_R
    t = np.linspace(0.0, 64.0, 2**16, endpoint=False)
    spec = np.abs(np.fft.rfft(pulse(t, 1.0)))
    f = np.fft.rfftfreq(t.size, t[1])
    assert f[np.argmax(f * spec)] == pytest.approx(F_PEAK_T, abs=1e-9)


def test_line_load_static_limit_is_flamant():
    """The step load's displacement grows as ``p (1 - nu) / (pi mu) ln(c_S t / x)``:
    between two distances, Flamant's ``p (1 - nu) / (pi mu) ln(x2 / x1)``."""
    from lamb import line_step_integrals

    q, h, _ = line_step_integrals(400.0, NU)
    late = np.searchsorted(q, [100.0, 200.0, 399.0])
    rest = h[late] - 2 * (1 - NU) * np.log(q[late])     # H = p/(2 pi mu) * this * 2 pi mu / p
    assert np.ptp(rest) < 2e-3 * abs(rest[-1])
    # the static difference u(x1) - u(x2) at a late time, against Flamant
    x1, x2, tq = 1.0, 3.0, 300.0
    diff = np.interp(tq / x1, q, h) - np.interp(tq / x2, q, h)
    assert diff / (2 * math.pi) == pytest.approx((1 - NU) / math.pi * math.log(x2 / x1),
                                                 rel=2e-3)


def test_line_load_far_field_is_the_rayleigh_pole():
    """Far away the body waves have decayed and the response is the pole's alone:
    ``u_z = p K_R / (2 mu) H[s](t - t_R)`` (H: the Hilbert transform), within 0.5 % at 20
    and 0.03 % at 80 pulse lengths (velocity)."""
    qr, k = rayleigh_slowness(NU), rayleigh_residue(NU)
    n, dt = 2**16, 1.0 / 256
    tt = np.arange(n) * dt - 64.0
    fr = np.fft.fftfreq(n, dt)
    hv = np.real(np.fft.ifft(-1j * np.sign(fr) * np.fft.fft(np.gradient(pulse(tt, 1.0), dt))))
    errors = []
    for x in (20.0, 80.0):
        t = qr * x + np.linspace(-3.0, 5.0, 801)
        _, v = lamb_line_response(x, t, 1.0, 1.0, 1.0, NU, 1.0)
        v_pole = k / 2 * np.interp(t - qr * x, tt, hv)
        errors.append(np.abs(v - v_pole).max() / np.abs(v_pole).max())
    assert errors[0] < 5e-3 and errors[1] < 3e-4, errors


# --------------------------------------------------------------------------- the FE runs
def _run(engine: str) -> dict:
    """The slab with ``engine`` (explicit, or IMEX with the elements within one wavelength
    of the load implicit): receiver velocities and displacements (in the load direction)
    and the reference."""
    from railvib_hpc.fem.dispersion import critical_courant
    from railvib_hpc.model.boundary import constraint_rules, face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_partition
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        initial_acceleration,
    )
    from railvib_hpc.transient.imex import ImexSystem
    from railvib_hpc.transient.integrate import DirectSolver, State, gather_values

    init_petsc([])
    t0 = time.perf_counter()
    h, lam = 1.0, float(EPW)
    nx, nz = int(round(X_MAX * EPW)), int(round(DEPTH * EPW))
    mesh = box_mesh((nx, 1, nz), (nx * h, h, nz * h), origin=(0, 0, -nz * h))
    case = soil_case(f"materials.subgrade.nu={NU}", "damping.model=none",
                     "modal.lumped_mass=true")
    mu = case["materials.subgrade.E"] / (2 * (1 + NU))
    c_s = math.sqrt(mu / RHO)
    c_p, c_r = c_s * math.sqrt(3.0), c_s / rayleigh_slowness(NU)
    duration = F_PEAK_T * lam / c_r
    dt = COURANT * critical_courant(NU) * h / c_p
    from railvib_hpc.problem import Problem

    problem = Problem.from_case(case)
    dofmap = build_dofmap(mesh, comm.size, rules=constraint_rules(problem),
                          node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm)
    if engine == "imex":
        centre = mesh.points[mesh.hexes].mean(axis=1)
        near = (centre[:, 0] < lam) & (centre[:, 2] > -lam)
        K_I, C_I = assemble_partition(mesh, problem, dofmap, comm, (), extra_hexes=near)
        system = ImexSystem(K, M, None, K_I, C_I, dt, comm)
    else:
        system = ExplicitSystem(K, M, None, dt, comm)
    on_line = np.isclose(mesh.points[:, 2], 0.0)
    src = np.flatnonzero(on_line & np.isclose(mesh.points[:, 0], 0.0))
    s_dofs = dofmap.index[src, 2]
    radii = [w * lam for w in RECEIVERS]
    rec = [np.flatnonzero(on_line & np.isclose(mesh.points[:, 0], r)
                          & np.isclose(mesh.points[:, 1], 0.0))[0] for r in radii]
    r_dofs = dofmap.index[rec, 2]

    def load(k):              # p h on the slab's two nodes, half of it on the half model
        return s_dofs, np.full(src.size, -0.25 * FORCE * h * float(pulse(k * dt, duration)))

    solver = ExplicitSolver(system, load) if engine == "explicit" else DirectSolver(system, load)
    n_local = system.r1 - system.r0
    st = State(0, np.zeros(n_local), np.zeros(n_local), np.zeros(n_local))
    if engine == "explicit":
        initial_acceleration(system, st, [load(0)])
    solver.start(st)
    nt = int(math.ceil((radii[-1] / c_r + 2.0 * duration) / dt))
    v, u = np.zeros((nt + 1, len(radii))), np.zeros((nt + 1, len(radii)))
    for n in range(nt):
        solver.step(st)
        v[n + 1] = -gather_values(comm, st.v, system.r0, r_dofs)
        u[n + 1] = -gather_values(comm, st.u, system.r0, r_dofs)
    solver.destroy()
    system.destroy()
    K.destroy()
    M.destroy()
    t = np.arange(nt + 1) * dt
    exact = [lamb_line_response(r, t, FORCE, mu, c_s, NU, duration) for r in radii]
    return {"t": t, "v": v, "u": u, "u_exact": np.array([e[0] for e in exact]).T,
            "v_exact": np.array([e[1] for e in exact]).T, "radii": radii, "dt": dt,
            "c_p": c_p, "c_s": c_s, "c_r": c_r, "duration": duration, "dofs": dofmap.n_dofs,
            "seconds": time.perf_counter() - t0}


def _peak(y: np.ndarray) -> float:
    """Largest ``|y|``, refined by the parabola through it and its neighbours."""
    y = np.abs(y)
    k = int(np.argmax(y))
    if 0 < k < len(y) - 1:
        a, b, c = y[k - 1], y[k], y[k + 1]
        return float(b + 0.125 * (a - c) ** 2 / (2 * b - a - c))
    return float(y[k])


def _onset(t: np.ndarray, v: np.ndarray, ve: np.ndarray, window: np.ndarray) -> float:
    """Largest difference [s] of the first times ``|v|`` and ``|ve|`` reach 10, 30, 50 %
    of the exact early phases' largest value in ``window``."""
    top = np.abs(ve[window]).max()
    tw, a, b = t[window], np.abs(v[window]), np.abs(ve[window])
    return max((tw[np.argmax(a >= f * top)] - tw[np.argmax(b >= f * top)]
                for f in (0.1, 0.3, 0.5)), key=abs)


def _check(run: dict, engine: str) -> list[float]:
    """Peak velocity of the Rayleigh pulse within 5 % at every receiver, the arrivals (see
    the test); returns the peak errors."""
    from test_verification import _lag

    t, dt, dur = run["t"], run["dt"], run["duration"]
    errors = []
    for j, r in enumerate(run["radii"]):
        v, ve = run["v"][:, j], run["v_exact"][:, j]
        t_p, t_s, t_r = r / run["c_p"], r / run["c_s"], r / run["c_r"]
        window = (t >= t_r - 0.5 * dur) & (t <= t_r + 2.0 * dur)
        err = _peak(v[window]) / _peak(ve[window]) - 1.0
        err_u = _peak(run["u"][window, j]) / _peak(run["u_exact"][window, j]) - 1.0
        errors.append(err)
        scale = np.abs(ve[window]).max()
        shift = (t[window][np.argmax(np.abs(v[window]))]
                 - t[window][np.argmax(np.abs(ve[window]))]) / dt
        early = (t >= t_p) & (t < t_r - 0.25 * dur)
        rayleigh = (t >= t_r - 0.25 * dur) & (t <= t_r + 1.5 * dur)
        lags = (_onset(t, v, ve, early) / dt, _lag(v, ve, rayleigh))
        misfit = np.linalg.norm(v[early] - ve[early]) / np.linalg.norm(ve[early])
        print(f"{engine} {r / EPW:g} wavelengths: peak velocity {err:+.4f}, displacement "
              f"{err_u:+.4f}; peak {shift:+.0f} steps; lags {lags[0]:+.2f} (P/S), "
              f"{lags[1]:+.2f} (R) steps; P/S misfit {misfit:.3f}; before P "
              f"{np.abs(v[t < t_p]).max() / scale:.1e}")
        assert abs(err) < 0.05, (r, err)
        # causal: nothing before the P front (the exact answer is 0 there)
        assert np.abs(ve[t < t_p]).max() == 0.0
        assert np.abs(v[t < t_p]).max() < 1e-3 * scale, r
        # the P and S phases (between t_P and the Rayleigh pulse, a smooth swell that
        # cross-correlation cannot time) rise when Lamb's kernel says: within 3 steps at
        # each level, and within 10 % RMS; the Rayleigh pulse within 4 steps (0.07 T; measured
        # 2.7-2.9 at 11 wavelengths, the dispersion's delay) by cross-correlation, its peak
        # within 5
        assert t_s < t_r
        assert abs(lags[0]) <= 3 and abs(lags[1]) <= 4, (r, lags)
        assert misfit < 0.1, (r, misfit)
        assert abs(shift) <= 5, (r, shift)
    print(f"{engine}: {run['dofs']:,} DOFs, {len(t) - 1} steps of {dt:.4g} s, "
          f"{run['seconds']:.1f} s on {comm.size} rank(s)")
    return errors


@pytest.fixture(scope="module", params=["explicit", "imex"])
def line_run(request):
    return request.param, _run(request.param)


@pytest.mark.slow
def test_lamb_line_load_at_ten_wavelengths(line_run):
    """Peak velocity of the Rayleigh pulse within 5 % of Lamb's line-load solution at 2, 5
    and 11 Rayleigh wavelengths, the P, S and Rayleigh arrivals (serial; the 2-rank twin
    below)."""
    if comm.size > 1:
        pytest.skip("the serial run (the mpi twin runs on 2 ranks)")
    _check(line_run[1], line_run[0])


@pytest.mark.slow
@pytest.mark.mpi
def test_lamb_line_load_at_ten_wavelengths_on_two_ranks(line_run):
    """The same on 2 ranks (``make test-slow``'s mpi pass): the same answer (the peak
    errors measured serially, within 1e-3)."""
    if comm.size == 1:
        pytest.skip("the 2-rank twin of the serial run")
    errors = _check(line_run[1], line_run[0])
    assert np.allclose(errors, SERIAL_ERRORS[line_run[0]], atol=1e-3), errors


#: The serial run's peak-velocity errors at the receivers (measured; the 2-rank run must
#: repeat them: the engines' sums are the same up to round-off).
SERIAL_ERRORS = {"explicit": (0.0167, 0.0213, -0.0214), "imex": (0.0175, 0.0242, -0.0270)}
