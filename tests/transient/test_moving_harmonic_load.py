"""A harmonic line load moving over the half-space, at ten wavelengths (issue 28, item 7).

A constant load moving below the Rayleigh speed radiates nothing in the steady state: its
field is a near field that moves with it, and "ten wavelengths" has no meaning for it
(docs/verification.md). A harmonic load ``P cos(2 pi f_0 t)`` does radiate: Rayleigh
waves of wavelength ``lambda_a = (c_R - c) / f_0`` ahead of it and ``lambda_b = (c_R + c)
/ f_0`` behind it, which in plane strain keep their amplitude at any distance. This is
the issue's "moving-load half-space case at >= 10 wavelengths".

Reference: :mod:`railvib_hpc.fem.halfspace_line` (the moving-frame Fourier integral of the
plane-strain surface compliance at the Doppler frequency ``omega_0 - c k``; its own
limits, Lamb's pole and Cole & Huth's moving load, are checked in
tests/fem/test_halfspace_line.py), with the FE load's spreading.

Model: a plane-strain slab (one hexahedron of ``h`` thick, ``u_y = 0``, as in
tests/transient/test_lamb_line.py), ``nu = 1/4``, no material damping, perfectly matched
layers on ``x_min``, ``x_max`` and the base (:mod:`pml_cases`), the explicit engine at its
allowed step. The load (:class:`~railvib_hpc.transient.surface_load.MovingSurfaceLoad`
with ``frequency``, the path of the case key ``load.frequency``) runs at ``c = c_R / 4``,
switched on over two periods, spread over ``+-2 h``. ``lambda_a = 12 h``,
``lambda_b = 20 h``.

The comparison is in the load's frame: at each ``xi = x - c t`` the FE's downward surface
velocity, interpolated along the surface (cubic splines), is a sinusoid of ``f_0`` once
the field is steady; its complex amplitude (least squares over the last periods) is
compared with ``V(xi)`` at 1, 2, 5 and 10 of the local wavelengths ahead and behind.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from mpi4py import MPI
from pml_cases import RHO, run_box, slab_mesh
from scipy.interpolate import CubicSpline

from railvib_hpc.fem.halfspace import rayleigh_mach_limit
from railvib_hpc.fem.halfspace_line import moving_harmonic_line_load

comm = MPI.COMM_WORLD
NU = 0.25
#: Young's modulus of the slab [Pa] (the subgrade of :mod:`pml_cases`): c_S 207.95 m/s.
E = 200e6
#: Element size [m]; elements per Rayleigh wavelength ahead of the load (the shortest):
#: the convergence test's meshes (the frequency changes with them) and the 2-rank run's.
H, EPW_AHEAD, EPW_TWO_RANKS = 1.0, (8, 12, 16), 8
#: Load speed over the Rayleigh speed.
SPEED_RATIO = 0.25
#: Line load amplitude [N/m]; its spreading's half-width [elements].
FORCE, SPREAD = 1e5, 2.0
#: Wavelengths at which the fields are compared, ahead (+) and behind (-).
WAVELENGTHS = (1.0, 2.0, 5.0, 10.0)
#: Switch-on, then periods before the fit window, then the fit window [periods of f_0]:
#: the field at ten wavelengths ahead or behind left the load ten periods earlier.
RAMP, SETTLE, FIT = 2.0, 12.0, 3.0
#: Elements between the farthest compared point and a layer; the layers' thickness; the
#: slab's depth without its layer [elements of the behind wavelength].
MARGIN, LAYER, DEPTH = 16, 10, 2.0
#: The issue's bound on the amplitude at ten wavelengths.
LIMIT = 0.05
#: The measured phase lag per wavelength against the grid's Rayleigh relation, relative,
#: on top of :data:`PHASE_FLOOR` (measured ahead: within 0.4-1.4 % at 8, 12, 16 per
#: wavelength).
PHASE_LIMIT = 0.05
#: Largest reflected energy of a layer measured at 0-60 degrees (8 elements; this slab's
#: layers have 10): 5.6e-5 (tests/transient/test_pml_oblique.py), an amplitude of 0.75 %.
LAYER_REFLECTED_ENERGY = 5.6e-5
#: The phase slope's floor [cycles per wavelength] that such a reflection sets: a wave of
#: relative amplitude R on top moves the phase by up to R / (2 pi) cycles, so the slope
#: fitted over the 9 wavelengths between the nearest and farthest compared points by up
#: to 2 R / (2 pi 9) = 2.6e-4. The grid's lag behind the load at 20-27 elements per
#: wavelength is only 1.5e-3 to 2.7e-3 per wavelength, so there the layer's share shows
#: (measured behind, 1 rank, the layers' mass at their Gauss points, on the meshes of 8 /
#: 12 / 16 per wavelength ahead: 0.00604 / 0.00261 / 0.00143 against 0.00622 / 0.00272 /
#: 0.00152 predicted, 0.9-1.8e-4 below and not falling with h; ahead within 0.4-1.4 %).
PHASE_FLOOR = 2.0 * math.sqrt(LAYER_REFLECTED_ENERGY) / (2.0 * math.pi * 9.0)


def _soil(epw: int):
    mu = E / (2 * (1 + NU))
    c_s = math.sqrt(mu / RHO)
    c_r = rayleigh_mach_limit(NU) * c_s
    speed = SPEED_RATIO * c_r
    f0 = (c_r - speed) / (epw * H)
    return mu, c_s, c_r, speed, f0


def run(epw: int, comm_=comm) -> dict:
    """The slab's run with ``epw`` elements per wavelength ahead of the load, and the
    complex amplitudes of the FE and the reference at the compared ``xi``."""
    from railvib_hpc.transient.surface_load import MovingSurfaceLoad, SurfaceLoadPath

    mu, c_s, c_r, speed, f0 = _soil(epw)
    lam_a, lam_b = (c_r - speed) / f0, (c_r + speed) / f0
    period = 1.0 / f0
    t_fit, t_end = (RAMP + SETTLE) * period, (RAMP + SETTLE + FIT) * period
    x_fit = speed * np.array([t_fit, t_end])              # the load during the fit
    xi = np.concatenate([-np.array(WAVELENGTHS)[::-1] * lam_b, np.array(WAVELENGTHS) * lam_a])
    lo = math.floor((x_fit[0] + xi[0]) / H) - MARGIN
    hi = math.ceil((x_fit[1] + xi[-1]) / H) + MARGIN
    depth = int(round(DEPTH * lam_b / H))
    mesh = slab_mesh(hi - lo + 2 * LAYER, depth + LAYER, H,
                     origin=((lo - LAYER) * H, 0.0, -(depth + LAYER) * H))
    faces = {"x_min": "pml", "x_max": "pml", "base": "pml", "y_min": "free",
             "y_max": "free"}
    surface = np.flatnonzero(np.isclose(mesh.points[:, 2], 0.0)
                             & np.isclose(mesh.points[:, 1], 0.0))
    surface = surface[np.argsort(mesh.points[surface, 0])]
    path = SurfaceLoadPath(forces=np.array([FORCE * H]), offsets=np.zeros(1), x_start=0.0,
                           y=0.5 * H, speed=speed, ramp_time=RAMP * period,
                           half_width=SPREAD * H, frequency=f0)

    def load(mesh_, dofmap, dt, steps):
        return MovingSurfaceLoad(mesh_, dofmap.index, path, dt, steps)

    t0 = time.perf_counter()
    out = run_box(mesh, faces, LAYER * H, None, mesh.points[surface], t_end, f0, comm_,
                  plane_strain=True, extra=(f"materials.subgrade.nu={NU}",), load=load)
    seconds = time.perf_counter() - t0
    x_nodes = mesh.points[surface, 0]
    window = out["t"] >= t_fit
    t = out["t"][window]
    v_down = -out["v"][window, :, 2]                      # (steps, surface nodes)
    samples = np.array([CubicSpline(x_nodes, v_down[n])(speed * t[n] + xi)
                        for n in range(t.size)])          # (steps, xi)
    basis = np.stack([np.cos(2 * math.pi * f0 * t), np.sin(2 * math.pi * f0 * t)], axis=1)
    coef = np.linalg.lstsq(basis, samples, rcond=None)[0]  # Re(V e^{iwt}) = a cos - b' sin
    v_fe = coef[0] - 1j * coef[1]
    _, v_ref = moving_harmonic_line_load(xi, FORCE, mu, NU, c_s, speed, f0, SPREAD * H)
    return {"xi": xi, "v_fe": v_fe, "v_ref": v_ref, "lam_a": lam_a, "lam_b": lam_b, "epw": epw,
            "c_r": c_r, "speed": speed, "courant": c_s * math.sqrt(3.0) * out["dt"] / H,
            "dofs": out["dofs"], "steps": len(out["t"]) - 1, "dt": out["dt"], "f0": f0,
            "seconds": seconds, "time_per_step": out["time_per_step"],
            "residual": float(np.linalg.norm(samples - basis @ coef)
                              / np.linalg.norm(samples))}


def _report(r: dict) -> str:
    err = np.abs(r["v_fe"]) / np.abs(r["v_ref"]) - 1
    phase = np.angle(r["v_fe"] / r["v_ref"]) / (2 * math.pi)
    lam = np.where(r["xi"] > 0, r["lam_a"], r["lam_b"])
    rows = [f"{x / l:+5.1f} wavelengths: |V| {abs(vr):.4e} m/s, FE {e:+.2%}, phase "
            f"{p:+.3f} cycles" for x, l, vr, e, p in zip(r["xi"], lam, r["v_ref"], err, phase)]
    return (f"moving harmonic line load, {r['epw']} elements per wavelength ahead, at "
            f"{r['f0']:.3f} Hz ({r['dofs']:,} DOFs, "
            f"{r['steps']} steps of {r['dt']:.3e} s, {r['seconds']:.1f} s on {comm.size} "
            f"rank(s); fit residual {r['residual']:.1e})\n  " + "\n  ".join(rows))


def phase_slopes(r: dict) -> tuple[np.ndarray, np.ndarray]:
    """Phase lag per wavelength travelled [periods], ahead and behind: measured (the FE's
    phase against the reference's, fitted over the compared wavelengths) and predicted
    (:func:`~railvib_hpc.fem.dispersion_rayleigh.rayleigh_wavenumber_ratio` at the wave's
    own elements per wavelength, lumped mass, central differences at the run's Courant
    number, times the Doppler factor ``c_R / (c_R -+ c)``)."""
    from railvib_hpc.fem.dispersion_rayleigh import rayleigh_wavenumber_ratio

    lag = -np.angle(r["v_fe"] / r["v_ref"]) / (2 * math.pi)
    ahead = r["xi"] > 0
    measured = np.array([np.polyfit(np.abs(r["xi"][side]) / lam, lag[side], 1)[0]
                         for side, lam in ((ahead, r["lam_a"]), (~ahead, r["lam_b"]))])
    epw = np.array([r["lam_a"], r["lam_b"]]) / H
    doppler = r["c_r"] / (r["c_r"] + np.array([-1.0, 1.0]) * r["speed"])
    grid = rayleigh_wavenumber_ratio(epw, nu=NU, mass="lumped", scheme="central",
                                     courant=r["courant"]) - 1.0
    return measured, grid * doppler


def assert_the_grid_lag(measured: np.ndarray, predicted: np.ndarray) -> None:
    """The measured phase lags per wavelength (ahead, behind) are the grid's Rayleigh
    relation's, within :data:`PHASE_LIMIT` of it plus the layers' :data:`PHASE_FLOOR`."""
    bound = PHASE_LIMIT * np.abs(predicted) + PHASE_FLOOR
    assert np.all(np.abs(measured - predicted) < bound), (measured, predicted, bound)


def _errors(r: dict) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude error (relative) and phase lag [cycles] per compared ``xi``."""
    return (np.abs(r["v_fe"]) / np.abs(r["v_ref"]) - 1,
            np.angle(r["v_fe"] / r["v_ref"]) / (2 * math.pi))


@pytest.mark.slow
@pytest.mark.skipif(comm.size > 1, reason="one rank (the 2-rank run below)")
def test_the_moving_harmonic_load_at_ten_wavelengths_converges_at_second_order():
    """At 12 and 16 elements per wavelength ahead (20 and 27 behind) the amplitude is within
    5 % at 1-10 wavelengths ahead and behind. The error is set near the load and does not
    grow with the distance (a harmonic wave keeps its amplitude; the grid's dispersion
    shifts its phase, which grows linearly); both fall as ``h^2``.

    Measured (1 rank, 25-34 s each): ahead at ten wavelengths +7.64 / +3.84 / +2.24 % and
    -0.313 / -0.131 / -0.072 cycles at 8 / 12 / 16 per wavelength; behind +2.2 / +1.0 /
    +0.6 %."""
    runs = [run(epw) for epw in EPW_AHEAD]
    for r in runs:
        print(_report(r))
        assert r["residual"] < 0.05, r["residual"]       # a steady sinusoid of f_0
    amp = np.array([_errors(r)[0] for r in runs])
    phase = np.array([_errors(r)[1] for r in runs])
    assert np.all(np.abs(amp[1:]) < LIMIT), amp
    epw = np.log(np.array(EPW_AHEAD, float))
    rate_amp = -np.polyfit(epw, np.log(np.abs(amp[:, -1])), 1)[0]
    rate_phase = -np.polyfit(epw, np.log(np.abs(phase[:, -1])), 1)[0]
    print(f"rates at ten wavelengths ahead: amplitude {rate_amp:.2f}, phase {rate_phase:.2f}")
    assert 1.6 < rate_amp < 2.4 and 1.6 < rate_phase < 2.4, (rate_amp, rate_phase)
    # the phase lag is the grid's Rayleigh dispersion, Doppler-amplified ahead
    for r in runs:
        measured, predicted = phase_slopes(r)
        print(f"{r['epw']} per wavelength: phase lag per wavelength ahead / behind measured "
              f"{measured[0]:.5f} / {measured[1]:.5f}, predicted {predicted[0]:.5f} / "
              f"{predicted[1]:.5f}")
        assert_the_grid_lag(measured, predicted)
    # the phase lag grows with the distance, the amplitude error does not
    ahead = runs[-1]["xi"] > 0
    assert abs(phase[-1, -1]) > 4 * abs(phase[-1, ahead][0])
    assert abs(amp[-1, -1]) < 1.5 * abs(amp[-1, ahead][0])


def _serial(folder):
    """The coarsest run alone on one rank (``serial_refs``' builder)."""
    from pathlib import Path

    r = run(EPW_TWO_RANKS, MPI.COMM_SELF)
    Path(folder).mkdir(parents=True, exist_ok=True)
    np.save(Path(folder) / "v_fe.npy", r["v_fe"])


#: The serial run the 2-rank test compares with (tests/conftest.py: ``serial_refs``):
#: seconds on one rank, builder.
SERIAL_REFERENCES = {"moving_harmonic_8": (10.0, _serial)}


@pytest.mark.slow
@pytest.mark.mpi
def test_the_moving_harmonic_load_on_two_ranks(serial_refs):
    """The 8-per-wavelength run on ``comm.size`` ranks gives the one-rank run's complex
    amplitudes at every compared point to round-off, and its phase lag per wavelength is
    the grid's Rayleigh relation's (as on one rank)."""
    r = run(EPW_TWO_RANKS)
    alone = np.load(serial_refs["moving_harmonic_8"] / "v_fe.npy")
    if comm.rank == 0:
        print(_report(r))
    diff = np.abs(r["v_fe"] - alone).max() / np.abs(alone).max()
    if comm.rank == 0:
        print(f"{comm.size} ranks against 1: {diff:.1e} of the largest amplitude")
    assert diff < 1e-9, diff
    measured, predicted = phase_slopes(r)
    assert_the_grid_lag(measured, predicted)
