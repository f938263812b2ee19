"""The divergence guard (:mod:`railvib_hpc.transient.guard`): its bound, and a diverging
run of every engine stopped in one line, with nothing written as a result.

The bound ``T_n <= B_n = E_0 + 1/2 dt^2 a_0^T M a_0 + W_n^+`` rests on three facts, each
checked here:

* the load work that the solvers sum (``solver.work``) closes each scheme's own energy
  balance to round-off (a closed, undamped box under a load that pushes and pulls);
* for one oscillator the kinetic energy stays below that bound for every ``omega dt``
  (every step up to the stability limit for central differences, damped or not; loads
  switched on over a step), and the generalized-alpha scheme's velocity overshoot of a
  start out of equilibrium stays below ``(1 - rho_inf)^2 / 16`` of ``1/2 (dt a_0)^2``;
* the coarse thesis model on each engine with an injected instability (a step 3 or 5 x
  the stability limit for the explicit and IMEX engines, the damping matrix negated for the
  direct engine, through the test hook :data:`~railvib_hpc.transient.guard.TEST_INJECTION`)
  stops with exit code 3 and one line naming the time and the part, and leaves no
  product; a rerun without the injection computes anew and finishes (direct engine).
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from transient_cases import BASELINE, TINY
from wave_cases import box_mesh, soil_case

from railvib_hpc.schema import PART_ID
from railvib_hpc.transient import guard
from railvib_hpc.transient.scheme import GeneralizedAlpha

comm = MPI.COMM_WORLD
#: Multiple of ``n_steps * eps`` that bounds the balance's round-off (as in
#: test_engine_energy.py: each step's sums carry a few eps of the largest term).
ROUNDOFF = 100.0
CLOSED = {"bottom": ("ux", "uy", "uz"), "x_faces": ("ux", "uy", "uz"),
          "y_faces": ("ux", "uy", "uz")}
#: Steps of the box runs, and the load: switched on over 40 steps, then reversed.
STEPS = 400


def _force(n: int) -> float:
    """A load that pushes, then pulls: the work changes sign."""
    return 1e4 * np.sin(np.pi * min(n, 40) / 80.0) ** 2 * np.cos(2 * np.pi * n / STEPS)


def _box_run(engine: str) -> dict:
    """Step a closed, undamped 4 x 4 x 4 box under a vertical load at a top node; the
    scheme's energy (the discrete one of the leapfrogs, the physical one of the
    trapezoidal rule) and the solver's summed load work."""
    from railvib_hpc.model.boundary import face_node_sets
    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble, assemble_partition
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.problem import Problem
    from railvib_hpc.transient.explicit import (
        ExplicitSolver,
        ExplicitSystem,
        initial_acceleration,
        lumped_diagonal,
        stability_limit,
    )
    from railvib_hpc.transient.imex import ImexSystem
    from railvib_hpc.transient.integrate import DirectSolver, State
    from railvib_hpc.transient.petsc import TransientSystem

    init_petsc([])
    mesh = box_mesh((4, 4, 4), (4.0, 4.0, 4.0))
    centre = mesh.points[mesh.hexes].mean(axis=1)
    if engine == "imex":
        top = (centre[:, 2] > 3.0) & np.all(np.abs(centre[:, :2] - 2.0) < 1.0, axis=1)
        mesh.hex_part[top] = PART_ID["slab"]
    problem = Problem.from_case(soil_case("modal.lumped_mass=true", "damping.model=none"))
    dofmap = build_dofmap(mesh, comm.size, rules=CLOSED, node_sets=face_node_sets(mesh))
    K, M, _ = assemble(mesh, problem, dofmap, comm)
    node = int(np.argmin(np.linalg.norm(mesh.points - [2.0, 2.0, 4.0], axis=1)))
    dof = np.array([dofmap.index[node, 2]])

    def load(n: int):
        return dof, np.array([_force(n)])

    m = lumped_diagonal(M, comm)
    dt = 0.9 * stability_limit(K, m, None, comm).dt_critical
    K_I = None
    if engine == "explicit":
        system = ExplicitSystem(K, M, None, dt, comm)
        solver = ExplicitSolver(system, load)
    elif engine == "imex":
        K_I, C_I = assemble_partition(mesh, problem, dofmap, comm, ("slab",), boundary=True)
        system = ImexSystem(K, M, None, K_I, C_I, dt, comm)
        solver = DirectSolver(system, load)
    else:
        system = TransientSystem(K, M, None, GeneralizedAlpha.from_radius(dt, 1.0), comm)
        solver = DirectSolver(system, load)
    n = system.r1 - system.r0
    st = State(0, np.zeros(n), np.zeros(n), np.zeros(n))
    if engine == "explicit":
        initial_acceleration(system, st, [load(0)])

    def energy() -> float:
        if engine == "direct":
            u, v = system.vector(st.u.copy()), system.vector(st.v.copy())
            out = system.energy(u, v)
            u.destroy()
            v.destroy()
            return out
        return system.scheme_energy(st.u, st.v, st.a)

    solver.start(st)
    e, work = [energy()], [0.0]
    for _ in range(STEPS):
        solver.step(st)
        e.append(energy())
        work.append(comm.allreduce(solver.work))
    solver.destroy()
    system.destroy()
    for A in (K, M):
        A.destroy()
    return {"e": np.array(e), "work": np.array(work)}


@pytest.mark.mpi
@pytest.mark.parametrize("engine", ["explicit", "imex", "direct"])
def test_the_load_work_closes_each_engines_energy_balance(engine):
    """``E_n - E_0`` equals the summed load work to round-off, while the work itself both
    rises and falls (so a wrong sign or a wrong time level of the load would show)."""
    r = _box_run(engine)
    e, work = r["e"], r["work"]
    scale = np.abs(e).max()
    residual = np.abs(e - e[0] - work).max() / scale
    print(f"{engine}: energy up to {scale:.3g} J, balance residual {residual:.2e} "
          f"= {residual / (STEPS * 2.2e-16):.2f} n eps")
    assert residual <= ROUNDOFF * STEPS * np.finfo(float).eps
    assert np.diff(work).min() < -1e-3 * scale < 1e-3 * scale < np.diff(work).max()


def _generalized_alpha_ratio(rho: float, omega_dt: float, ramp: int, sudden: bool) -> float:
    """One oscillator, ``dt = 1``: the largest ``(T_n - W_n^+) / 1/2 a_0^2`` (``sudden``:
    a unit load on from t = 0 at rest, ``a_0 = 1``) or ``T_n / W_n^+`` (a load switched on
    over ``ramp`` steps)."""
    s = GeneralizedAlpha.from_radius(1.0, rho)
    w2 = omega_dt ** 2
    h = s.history()
    k_eff = s.c_mass + s.c_stiffness * w2
    wf0, wf1 = s.load_weights()

    def f(n: int) -> float:
        return 1.0 if sudden else min(n / ramp, 1.0)

    u, v, a = 0.0, 0.0, f(0)
    w_plus, worst = 0.0, 0.0
    for n in range(300):
        fe = wf0 * f(n) + wf1 * f(n + 1)
        rhs = fe + h["M"][0] * u + h["M"][1] * v + h["M"][2] * a + h["K"][0] * w2 * u
        u1 = rhs / k_eff
        v, a = s.update(u1, u, v, a)
        w_plus += max(fe * (u1 - u), 0.0)
        u = u1
        if sudden:
            worst = max(worst, (0.5 * v * v - w_plus) / 0.5)
        elif w_plus > 0:
            worst = max(worst, 0.5 * v * v / w_plus)
    return worst


@pytest.mark.parametrize("rho", [1.0, 0.9, 0.5, 0.0])
def test_generalized_alpha_kinetic_energy_stays_below_the_bound(rho):
    """Loads switched on over one step or more: ``T_n <= W_n^+`` for every ``omega dt``
    up to 1e4; a load on at rest from t = 0: the overshoot above ``W_n^+`` is below
    ``(1 - rho)^2 / 16`` of ``1/2 (dt a_0)^2`` (none for the trapezoidal rule), which the
    guard's bound holds in full."""
    omegas = np.logspace(-2, 4, 50)
    ramped = max(_generalized_alpha_ratio(rho, w, r, False) for w in omegas for r in (1, 3, 20))
    sudden = max(_generalized_alpha_ratio(rho, w, 1, True) for w in omegas)
    print(f"rho_inf {rho}: T / W+ <= {ramped:.6f}; overshoot {sudden:.3g} of 1/2 (dt a0)^2")
    assert ramped <= 1.0 + 1e-9
    assert sudden <= (1.0 - rho) ** 2 / 16 + 1e-12


@pytest.mark.parametrize("xi", [0.0, 0.05, 1.0, 3.0])
def test_central_differences_kinetic_energy_stays_below_the_bound(xi):
    """Central differences, damping at the half-step velocity, steps up to 0.99 of the
    damped critical step: ``T_n <= E_{1/2} + W_n^+`` (an initial velocity, or a load
    switched on over 1-20 steps)."""
    from railvib_hpc.transient.explicit import critical_step

    def worst(fraction: float, ramp: int, moving: bool) -> float:
        h = fraction * critical_step(1.0, xi)
        c = 2.0 * xi

        def f(n: int) -> float:
            return 0.0 if moving else min(n / ramp, 1.0)

        u, v = 0.0, 1.0 if moving else 0.0
        a = f(0) - c * v
        bound, out = 0.5 * v * v, 0.0
        for n in range(400):
            u1 = u + h * v + 0.5 * h * h * a
            v_half = v + 0.5 * h * a
            a = f(n + 1) - u1 - c * v_half
            v = v_half + 0.5 * h * a
            u = u1
            bound += max(h * f(n + 1) * v, 0.0)
            out = max(out, 0.5 * v * v / bound)
        return out

    ratio = max(worst(fr, r, m) for fr in (0.1, 0.5, 0.9, 0.99) for r in (1, 3, 20)
                for m in (False, True))
    print(f"xi {xi}: T / B <= {ratio:.4f}")
    assert ratio <= 1.0 + 1e-12


# ----------------------------------------------------------------------- diverging runs
#: The injection per engine: the step 3 (5) x the pre-checked one, or the damping negated;
#: each diverges within the passage of :data:`SHORT` (measured: explicit at 12 ms, IMEX at
#: 18 ms, direct at 12 ms).
INJECTIONS = {"explicit": guard.Injection("step", 3.0), "imex": guard.Injection("step", 5.0),
              "direct": guard.Injection("negative_damping", 1.0)}
#: What a diverged run must not leave in its folder.
PRODUCTS = ("fields.h5", "probes.h5", "transient.h5", "assessment.json", "report.md",
            "fields.xdmf", ".fields.h5.resume", "transient_checkpoint.h5")


#: The tiny case's passage cut to 20 ms (the wheel enters the flexible rail at 10 ms).
SHORT = [*TINY, "vehicle.x_end=3.3", "output.stress_times=[]"]


def _cli(engine: str, out) -> list[str]:
    sets = [*SHORT, f"transient.engine={engine}"]
    if engine != "direct":
        sets.append("modal.lumped_mass=true")
    return ["transient", str(BASELINE), "--out", str(out),
            *(w for s in sets for w in ("--set", s))]


@pytest.mark.mpi
@pytest.mark.parametrize("engine", ["explicit", "imex", "direct"])
def test_a_diverging_run_stops_in_one_line_and_leaves_no_result(engine, shared_tmp,
                                                                 monkeypatch, capsys):
    from railvib_hpc.cli import run

    out = shared_tmp / "run"
    monkeypatch.setattr(guard, "TEST_INJECTION", INJECTIONS[engine])
    code = run(_cli(engine, out))
    captured = capsys.readouterr()
    assert code == 3, captured.err
    if comm.rank == 0:
        lines = [ln for ln in captured.err.splitlines() if ln.strip()]
        assert len(lines) == 1, captured.err
        line = lines[0]
        print(line)
        assert line.startswith("railvib transient: error: the time integration diverged at "
                               "t = 0.0")
        assert " x what the initial state and the loads can have put in" in line \
            or "have put in nothing" in line or "no longer finite" in line
        assert "it grows in part " in line and "likely cause: " in line \
            and "change: " in line
        assert "assessed" not in captured.out and "limits exceeded" not in captured.out
        assert "Traceback" not in captured.err
    comm.Barrier()
    left = [name for name in PRODUCTS if (out / name).exists()]
    assert not left
    if engine != "direct":
        return
    # a rerun without the injection reuses and resumes nothing of the diverged run (the
    # clean-up is the stage's, the same for every engine: checked once, on the cheapest)
    monkeypatch.setattr(guard, "TEST_INJECTION", None)
    assert run(_cli(engine, out)) == 0
    text = capsys.readouterr().out
    if comm.rank == 0:
        assert "reusing the transient results" not in text and "resuming" not in text
        assert "divergence guard: " in text and "transient complete: " in text


@pytest.mark.mpi
@pytest.mark.parametrize("diverging", [True, False])
def test_a_contact_newton_failure_stops_in_one_line_as_a_divergence(diverging, shared_tmp,
                                                                    monkeypatch, capsys,
                                                                    failing_contact_newton):
    """The contact Newton fails before the next check: on a slow machine the guard's
    interval widens to its most steps (emulated: a cost share of 1e-9), and a rail grown
    without bound stalls the Newton at round-off (emulated: its relative floor off). The
    guard checks the last good state at once and names the growth (``diverging``); a
    failure with nothing grown (the Newton made to fail at its fifth call) is reported
    with its time and what to change. Exit code 3 either way, nothing left as a result."""
    from railvib_hpc.cli import run
    from railvib_hpc.mbs import integrate

    out = shared_tmp / "run"
    monkeypatch.setattr(guard, "GUARD_COST_SHARE", 1e-9)
    if diverging:
        monkeypatch.setattr(guard, "TEST_INJECTION", INJECTIONS["direct"])
        monkeypatch.setattr(integrate, "NEWTON_ROUNDOFF", 0.0)
    else:
        failing_contact_newton(5)
    code = run(_cli("direct", out))
    captured = capsys.readouterr()
    assert code == 3, captured.err
    if comm.rank == 0:
        lines = [ln for ln in captured.err.splitlines() if ln.strip()]
        assert len(lines) == 1, captured.err
        if diverging:
            assert lines[0].startswith("railvib transient: error: the time integration "
                                       "diverged at t = 0.0")
            assert "it grows in part rail" in lines[0]
        else:
            assert lines[0].startswith("railvib transient: error: the time integration "
                                       "failed at t = 0.0")
            assert "Newton iteration did not converge in 50 iterations" in lines[0]
            assert "change: a smaller transient.dt" in lines[0]
        assert "nothing was written as a result" in lines[0]
        assert "Traceback" not in captured.err
    comm.Barrier()
    assert not [name for name in PRODUCTS if (out / name).exists()]
