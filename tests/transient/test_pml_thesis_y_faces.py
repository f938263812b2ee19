"""Perfectly matched layers on the coarse thesis model where they cut through the track
bed's toe, the layered soil and the soil beside the building (slow tier).

Before the layer's mass side took the profile at the Gauss points (docs/transient.md,
"Where the layer meets coarse elements"), this command diverged and was assessed::

    railvib transient jobs/thesis_baseline.toml --set mesh.refinement=0.5 \\
      --set output.stress_times=[] --set modal.lumped_mass=true --set transient.engine=imex \\
      --set boundary.layer_thickness=4 --set domain.extra_depth=4 \\
      --set domain.extra_length=4 --set domain.extra_width=4 \\
      --set boundary.y_min=pml --set boundary.y_max=pml

(ground_toe's largest |a_z| per 0.1 s: 5.9e-3, 6.9e-3, 1.5e-2, 4.8e-2, 0.27, 2.1, 17, 134,
193 m/s^2), and with layers on all five faces a 10 s undamped run grew 1e8-fold per
second (measured: 1.9e69 J at 10 s).
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE

from railvib_hpc.config import load_case
from railvib_hpc.log import Reporter
from railvib_hpc.transient.stage import run_transient_stage

comm = MPI.COMM_WORLD
#: The command above, the wheelset stopped at x = 21 m (0.7 s: before the fix ground_toe's
#: largest |a_z| in the last 0.1 s was 2.1 m/s^2, 50 x the roller run's peak).
REPRO = ["mesh.refinement=0.5", "output.stress_times=[]", "modal.lumped_mass=true",
         "transient.engine=imex", "boundary.layer_thickness=4", "domain.extra_depth=4",
         "domain.extra_length=4", "domain.extra_width=4", "boundary.y_min=pml",
         "boundary.y_max=pml", "vehicle.x_end=21", "transient.checkpoint_interval=0"]
#: Its 0.1 s windows.
WINDOWS = 7
#: The same domain 8 m wider on each y side: beyond the building (domain.extra_width 4 ->
#: 12 m) and beyond the far toe (geometry.ys0 8.25 -> 16.25 m), the same layers.
WIDER = [*REPRO, "domain.extra_width=12", "geometry.ys0=16.25"]
#: The probes by the track, whose peaks are the direct field's.
TRACK_PROBES = ("ground_toe", "ground_mid")
#: Their peak |a| and |v| against the wider domain [-]. The layers are one element across
#: on y_max and half of one on y_min (the run warns that their reflection is far above
#: boundary.pml_reflection), and the two domains' meshes differ beside the track (its y
#: grading); the peak |a| is the passing wheel's direct field, the peak |v| mostly the
#: quasi-static bowl under it, which feels the box's static compliance. Measured to 0.7 s:
#: |a| +1.4 % (ground_toe) and +3.0 % (ground_mid), |v| -8.8 % and -6.8 %.
TRACK_TOL_A, TRACK_TOL_V = 0.05, 0.12
#: Every probe's peak |v| and |a| against the wider domain, a factor [-]: the largest,
#: 2.65 in |a| and 2.2 in |v|, at ground_opposite, which stands on the y_max layer's inner
#: face; the building's probes 13-32 % (over the whole passage the same y faces fixed miss
#: by up to 3.0 x, 84 % in the building); before the fix the probes were 100-4000 x off.
ANY_FACTOR = 3.5
#: 2 ranks against 1, the largest probe velocity difference relative to its peak [-]:
#: the implicit partition's MUMPS factor is not reproducible to the bit in parallel (two
#: uninterrupted 2-rank runs of the coarse passage differ by ~4e-9, docs/transient.md) and
#: the Hertz contact carries it on; measured 6.9e-9 after the 2,100 steps.
RANKS_TOL = 3e-8
#: ground_toe's largest |a_z| [m/s^2]: 2.3 x the roller run's 0.044 (this run: 0.043).
TOE_LIMIT = 0.1


def _probes(folder) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    with h5py.File(folder / "probes.h5", "r") as f:
        return {name: (g["time"][()], g["velocity"][()], g["acceleration"][()])
                for name, g in f["probes"].items()}


def _peaks(probes) -> dict[str, tuple[float, float]]:
    return {name: (float(np.linalg.norm(v, axis=1).max()),
                   float(np.linalg.norm(a, axis=1).max())) for name, (_, v, a) in
            probes.items()}


def _bounded(probes) -> None:
    """ground_toe's largest |a_z| below :data:`TOE_LIMIT`, its last 0.1 s below its
    largest (a growing run's last window is its largest)."""
    t, _, a = probes["ground_toe"]
    az = np.abs(a[:, 2])
    windows = [az[(t >= k / 10) & (t < (k + 1) / 10)].max() for k in range(WINDOWS)]
    assert max(windows) < TOE_LIMIT and windows[-1] < max(windows), windows


def _run(overrides, folder, comm_) -> dict:
    run_transient_stage(load_case(BASELINE, overrides), folder, comm_, Reporter(comm_.rank))
    return _probes(folder) if comm_.rank == 0 else {}


def _matches_the_wider_domain(mine: dict, ref: dict) -> None:
    """Peak |v| and |a| of the probes by the track within 12 % and 5 % of the wider
    domain's, every probe's within a factor 3.5 (see the constants)."""
    for name in TRACK_PROBES:
        for x, y, tol in zip(mine[name], ref[name], (TRACK_TOL_V, TRACK_TOL_A)):
            assert abs(x / y - 1) < tol, (name, mine[name], ref[name])
    for name, (v, acc) in mine.items():
        for x, y in ((v, ref[name][0]), (acc, ref[name][1])):
            assert 1 / ANY_FACTOR < x / y < ANY_FACTOR, (name, mine[name], ref[name])


def _build(overrides):
    def build(folder) -> None:
        run_transient_stage(load_case(BASELINE, overrides), folder, MPI.COMM_SELF,
                            Reporter(0))
    return build


#: The serial runs of the test below (tests/conftest.py ``serial_refs``): the command
#: alone on one rank and the wider domain alone on one rank, built side by side by the
#: two ranks: name -> (seconds on one rank, measured; builder).
SERIAL_REFERENCES = {"y_faces": (46.0, _build(REPRO)),
                     "y_faces_wider": (50.0, _build(WIDER))} if comm.size > 1 else {}


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.skipif(comm.size == 1, reason="the 1-rank run is its serial reference")
def test_the_y_face_layers_on_1_and_2_ranks_stay_bounded_and_match_a_wider_domain(
        shared_tmp, serial_refs):
    """The command above to x = 21 m alone on one rank (``serial_refs``) and on 2 ranks
    (the layers' elements at the partition computed on both, their nodes gathered): each
    bounded, ground_toe below 0.1 m/s^2 and falling in its last 0.1 s (before the fix its
    last 0.1 s held 2.1 m/s^2); the one-rank run's peaks match the wider domain's (also
    alone on one rank; see :func:`_matches_the_wider_domain`); the 2-rank probes'
    velocities equal the one-rank run's within 3e-8 of their peak (see RANKS_TOL)."""
    probes = _run(REPRO, shared_tmp / f"y_faces_{comm.size}", comm)
    verdict = None
    if comm.rank == 0:           # (checked on rank 0, asserted on every rank: none waits)
        try:
            alone = _probes(serial_refs["y_faces"])
            _bounded(alone)
            _matches_the_wider_domain(_peaks(alone), _peaks(_probes(
                serial_refs["y_faces_wider"])))
            _bounded(probes)
            worst = max(np.abs(v - alone[name][1]).max()
                        / max(np.abs(alone[name][1]).max(), 1e-30)
                        for name, (_, v, _) in probes.items())
            assert worst < RANKS_TOL, worst
        except AssertionError as exc:
            verdict = str(exc)
    verdict = comm.bcast(verdict, root=0)
    assert verdict is None, verdict


#: The ten-second run: the model of :data:`REPRO` with layers on all five faces, undamped,
#: constant moving forces (the wheelset's static loads, so that the loads' work is the
#: work of known forces), the direct engine at 0.01 s.
TEN_SECONDS = [*REPRO[:-3], *(f"boundary.{f}=pml" for f in ("x_min", "x_max", "y_min",
                                                              "y_max", "base")),
               "transient.engine=direct", "damping.model=none", "vehicle.type=moving_force",
               "output.dt=0.01", "transient.dt=0.01", "transient.checkpoint_interval=0"]
#: The largest energy against the largest work the loads have done so far [-]: the
#: energy 1/2 v'Mv + 1/2 u'Ku counts the layers' region with the soil's K, and their
#: quasi-static field is the stretched problem's (at s -> 0 a layer is 1 + d / alpha,
#: ~380 x, longer across), so it may exceed the work by what the layers hold: measured
#: 1.28 while the forces roll over the rail; a growing run exceeds any bound (1.9e69 J
#: at 10 s before the fix, against 0.24 J of work).
WORK_FACTOR = 1.5


def _ten_second_run(folder):
    """Step the direct engine through the stage's own setup, recording the energy and the
    loads' work ``sum 1/2 (f_n + f_{n+1}) . (u_{n+1} - u_n)`` every step (Newmark's
    average acceleration conserves ``E - W`` without damping and layers)."""
    from railvib_hpc.io.stage_protocol import StageContext
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.engines import initial_state
    from railvib_hpc.transient.integrate import add_sparse
    from railvib_hpc.transient.stage import _setup

    init_petsc([])
    case = load_case(BASELINE, TEN_SECONDS)
    passage = _setup(StageContext(case, folder, MPI.COMM_SELF, Reporter(0)))
    for key in ("system", "K", "M"):
        passage[key].destroy()
    case = case.replace({"vehicle.t_after": 10.0 - passage["nt"] * passage["dt"]})
    ctx = StageContext(case, folder, MPI.COMM_SELF, Reporter(0))
    init = _setup(ctx)              # (the mesh of the first setup reused)
    system, solver = init["system"], init["solver"]
    st = initial_state(init, MPI.COMM_SELF, ctx.rep)
    solver.start(st)

    def load(n):
        f = np.zeros(st.u.size)
        dofs, values = init["prescribed"](n)
        add_sparse(f, system.r0, dofs, values)
        return f

    def energy() -> float:
        u, v = system.vector(st.u.copy()), system.vector(st.v.copy())
        try:
            return system.energy(u, v)
        finally:
            u.destroy()
            v.destroy()

    energies, work, f0 = [energy()], [0.0], load(0)
    try:
        for _ in range(init["nt"]):
            u0 = st.u.copy()
            solver.step(st)
            f1 = load(st.step)
            work.append(work[-1] + float(0.5 * (f0 + f1) @ (st.u - u0)))
            energies.append(energy())
            f0 = f1
    finally:
        solver.destroy()
        system.destroy()
    return np.arange(init["nt"] + 1) * init["dt"], np.array(energies), np.array(work)


@pytest.mark.slow
def test_a_10_s_undamped_run_with_layers_on_five_faces_stays_bounded(tmp_path):
    """10 s (1,000 steps of the direct engine, whose trapezoidal rule maps the
    semi-discrete spectrum's right half-plane, and only it, outside the unit circle: it
    tests the layers at any step): the energy never above 1.5 x the largest work the
    loads have done so far, every second after the passage (1 s) holding less than the
    one before, the end below 2 % of the peak (measured: peak 0.300 J at 0.43 s, at most
    1.28 x the work so far; the seconds after the passage 0.024, 0.011, 0.0087, 0.0071,
    0.0060, 0.0052, 0.0047, 0.0043, 0.0040 J; the end 1.3 % of the peak; before the fix
    1e8 x per second, 1.9e69 J at 10 s)."""
    t, e, w = _ten_second_run(tmp_path)
    assert t[-1] > 9.99
    assert np.all(e <= WORK_FACTOR * np.maximum.accumulate(w) + 1e-12 * e.max()), \
        float(np.max(e / np.maximum(np.maximum.accumulate(w), 1e-30)))
    per_second = [e[(t >= k) & (t < k + 1)].max() for k in range(10)]
    assert all(b < a for a, b in zip(per_second[1:], per_second[2:])), per_second
    assert e[-1] < 0.02 * e.max(), (e[-1], e.max())
