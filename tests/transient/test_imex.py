"""The implicit-explicit engine (issue 28): the Hughes-Liu step against a dense reference,
its stability limit (the explicit part's alone), and the damping velocity's factor."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mpi4py import MPI
from wave_cases import box_mesh, smooth_pulse, soil_case

from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID
from railvib_hpc.transient.explicit import critical_step
from railvib_hpc.transient.imex import DAMPING_STABILITY_FACTOR, implicit_part_names

comm = MPI.COMM_WORLD
RULES = {"bottom": ("ux", "uy", "uz")}


def _scalar_map(omega: float, xi: float, h: float) -> np.ndarray:
    """One IMEX step of ``u'' + 2 xi omega u' + omega^2 u = 0`` for an explicit element:
    Newmark predictors, the damping at ``v* = v + h a`` (written out independently of
    :mod:`railvib_hpc.transient.imex`)."""
    b, g = 0.25, 0.5
    u_t = np.array([1.0, h, h * h * (0.5 - b)])
    v_t = np.array([0.0, 1.0, h * (1.0 - g)])
    v_star = np.array([0.0, 1.0, h])
    a1 = -omega * omega * u_t - 2.0 * xi * omega * v_star
    return np.array([u_t + b * h * h * a1, v_t + g * h * a1, a1])


def _scalar_critical(omega: float, xi: float) -> float:
    lo, hi = 0.0, 2.0 / omega
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        stable = np.abs(np.linalg.eigvals(_scalar_map(omega, xi, mid))).max() <= 1 + 1e-12
        lo, hi = (mid, hi) if stable else (lo, mid)
    return lo


@pytest.mark.parametrize("xi", [0.0, 0.05, 0.234, 1.0])
def test_the_damping_velocity_halves_the_damped_critical_step_as_twice_the_ratio(xi):
    """The explicit part's critical step with the damping at ``v*`` is the central
    differences' at ``DAMPING_STABILITY_FACTOR`` times the damping ratio."""
    assert _scalar_critical(1000.0, xi) == pytest.approx(
        critical_step(1000.0, DAMPING_STABILITY_FACTOR * xi), rel=1e-6)


def test_the_damping_velocity_is_second_order():
    """The damping ratio of the scheme's oscillation converges as dt^2 to the exact one."""
    xi, errors, hs = 0.05, [], np.array([0.1, 0.05, 0.025])
    for h in hs:
        ev = np.linalg.eigvals(_scalar_map(1.0, xi, h))
        lam = np.log(ev[np.argmax(np.abs(ev))]) / h
        errors.append(abs(-lam.real / abs(lam) - xi))
    rate = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert 1.8 < rate < 2.2, (errors, rate)


def test_implicit_groups_expand_to_the_parts_of_the_mesh():
    present = ["rail", "rigid_rail", "sleeper", "pad_z", "ballast", "subgrade", "slab", "wall"]
    assert implicit_part_names(["track"], present) == ("pad_z", "rail", "rigid_rail",
                                                       "sleeper")
    assert implicit_part_names(["building", "ballast"], present) == ("ballast", "slab", "wall")
    assert implicit_part_names([], present) == ()


class BoxModel:
    """A 4 x 4 x 3 soil box with a stiff concrete top layer ("slab": the implicit part),
    bottom fixed, Rayleigh damping, lumped mass; its matrices on ``comm`` and, dense, on
    this rank alone (global DOF numbers are the same on any number of ranks)."""

    def __init__(self, damping: str = "rayleigh"):
        from railvib_hpc.model.dofmap import build_dofmap
        from railvib_hpc.model.petsc import assemble, assemble_damping, assemble_partition
        from railvib_hpc.petsc_env import init_petsc

        init_petsc([])
        mesh = box_mesh((4, 4, 3), (4.0, 4.0, 1.5))
        top = mesh.points[mesh.hexes].mean(axis=1)[:, 2] > 1.0
        mesh.hex_part[top] = PART_ID["slab"]
        self.mesh = mesh
        self.case = soil_case("modal.lumped_mass=true", f"damping.model={damping}",
                              "damping.f1=5", "damping.f2=80")
        self.dense = {}
        for c, name in ((comm, "dist"), (MPI.COMM_SELF, "dense")):
            dofmap = build_dofmap(mesh, c.size, rules=RULES)
            K, M, _ = assemble(mesh, Problem.from_case(self.case), dofmap, c)
            C = (assemble_damping(mesh, Problem.from_case(self.case), dofmap, c, K, M)[0]
                 if damping != "none" else None)
            K_I, C_I = assemble_partition(mesh, Problem.from_case(self.case), dofmap, c, ("slab",))
            mats = {"K": K, "M": M, "C": C, "K_I": K_I, "C_I": C_I}
            if name == "dist":
                self.dofmap, self.mats = dofmap, mats
            else:
                for key, A in mats.items():
                    self.dense[key] = (np.zeros((dofmap.n_dofs,) * 2) if A is None
                                       else A.convert("dense").getDenseArray().copy())
                    if A is not None:
                        A.destroy()
        self.n = self.dofmap.n_dofs
        self.m = np.diag(self.dense["M"]).copy()
        self.r0, self.r1 = self.mats["K"].getOwnershipRange()

    def limit(self):
        from railvib_hpc.transient.explicit import lumped_diagonal, stability_limit

        m = lumped_diagonal(self.mats["M"], comm)
        return stability_limit(self.mats["K"], m, self.mats["C"], comm,
                               minus=(self.mats["K_I"], self.mats["C_I"]),
                               damping_factor=DAMPING_STABILITY_FACTOR)

    def step_map(self, dt: float) -> np.ndarray:
        """The dense one-step map of ``(u, v, a)`` (Hughes-Liu, damping at ``v*``)."""
        d = self.dense
        b, g, n = 0.25, 0.5, self.n
        m_star = np.diag(self.m) + g * dt * d["C_I"] + b * dt * dt * d["K_I"]
        eye, zero = np.eye(n), np.zeros((n, n))
        u_t = np.hstack([eye, dt * eye, dt * dt * (0.5 - b) * eye])
        v_t = np.hstack([zero, eye, dt * (1 - g) * eye])
        v_star = np.hstack([zero, eye, dt * eye])
        c_e = d["C"] - d["C_I"]
        a1 = -np.linalg.solve(m_star, d["K"] @ u_t + d["C_I"] @ v_t + c_e @ v_star)
        return np.vstack([u_t + b * dt * dt * a1, v_t + g * dt * a1, a1])

    def destroy(self):
        for key in ("M",):
            self.mats[key].destroy()
        for key in ("K", "C"):
            if self.mats[key] is not None:
                self.mats[key].destroy()


@pytest.mark.mpi
def test_imex_step_is_the_hughes_liu_step():
    """200 steps of the engine (ImexSystem + DirectSolver, a pulse on the top) against the
    dense Hughes-Liu recursion of the same matrices, on 1 and 2 ranks, to round-off."""
    from railvib_hpc.transient.imex import ImexSystem
    from railvib_hpc.transient.integrate import DirectSolver, State, gather_values

    model = BoxModel()
    dt = 0.9 * model.limit().dt_allowed
    mats = model.mats
    system = ImexSystem(mats["K"], mats["M"], mats["C"], mats["K_I"], mats["C_I"], dt, comm)
    top = np.flatnonzero(np.isclose(model.mesh.points[:, 2], 1.5))
    dofs = model.dofmap.index[top, 2]
    duration = 20 * dt

    def load(n):
        return dofs, np.full(top.size, -1e4) * smooth_pulse(n * dt, duration)

    solver = DirectSolver(system, load)
    nl = model.r1 - model.r0
    st = State(0, np.zeros(nl), np.zeros(nl), np.zeros(nl))
    solver.start(st)
    T = model.step_map(dt)
    f = np.zeros(model.n)
    x = np.zeros(3 * model.n)
    m_star = (np.diag(model.m) + 0.5 * dt * model.dense["C_I"]
              + 0.25 * dt * dt * model.dense["K_I"])
    for n in range(200):
        solver.step(st)
        f[:] = 0.0
        np.add.at(f, load(n + 1)[0], load(n + 1)[1])
        a_f = np.linalg.solve(m_star, f)
        x = T @ x + np.concatenate([0.25 * dt * dt * a_f, 0.5 * dt * a_f, a_f])
    u = gather_values(comm, st.u, model.r0, np.arange(model.n))
    assert np.abs(x[:model.n]).max() > 0
    assert np.abs(u - x[:model.n]).max() <= 1e-10 * np.abs(x[:model.n]).max()
    system.destroy()
    model.destroy()


@pytest.mark.mpi
@pytest.mark.parametrize("damping", ["none", "rayleigh"])
def test_imex_is_stable_up_to_the_explicit_parts_limit(damping):
    """The limit is the largest frequency of ``K - K_I`` on the lumped mass (dense check);
    the dense one-step map is stable at the allowed step and, undamped, unstable 2 % above
    the critical one; the stiff implicit top would hold pure central differences to a
    step several times smaller."""
    from scipy.linalg import eigh

    model = BoxModel(damping)
    lim = model.limit()
    d = model.dense
    lam_e = eigh(d["K"] - d["K_I"], np.diag(model.m), eigvals_only=True).max()
    lam_all = eigh(d["K"], np.diag(model.m), eigvals_only=True).max()
    assert lim.omega_max == pytest.approx(math.sqrt(lam_e), rel=1e-5)
    assert math.sqrt(lam_all) > 3.0 * lim.omega_max
    # Rayleigh damping on the soil alone is (nearly) proportional to the explicit part's
    # largest mode: the whole-map limit is that mode's at twice its ratio, or below it
    critical = lim.dt_critical
    assert critical <= critical_step(lim.omega_max, DAMPING_STABILITY_FACTOR * lim.xi) \
        * (1 + 1e-6)
    rho = np.abs(np.linalg.eigvals(model.step_map(0.9 * critical))).max()
    assert rho <= 1.0 + 1e-9, rho
    if damping == "none":
        rho = np.abs(np.linalg.eigvals(model.step_map(1.02 * critical))).max()
        assert rho > 1.0 + 1e-6, rho
    for key in ("K_I", "C_I"):
        if model.mats[key] is not None:
            model.mats[key].destroy()
    model.destroy()


def test_damped_critical_steps_is_the_central_differences_limit_at_twice_the_ratio():
    from railvib_hpc.transient.imex import damped_critical_steps

    omega = np.array([300.0, 1000.0, 5000.0])
    alpha, beta = 2.0, 2e-4
    got = damped_critical_steps(omega, alpha, beta)
    for w, dt in zip(omega, got):
        xi = alpha / (2 * w) + beta * w / 2
        assert dt == pytest.approx(critical_step(w, DAMPING_STABILITY_FACTOR * xi), rel=1e-9)


def test_auto_partition_takes_the_thin_elements_and_bounds_the_model():
    """A soil box whose top layer is 10 x thinner: the element-wise partition takes exactly
    that layer (target between the two element steps), the share cap bounds it, and the
    model's largest frequency is at most the largest element's (Irons)."""
    from railvib_hpc.model.elements import hex_max_frequencies
    from railvib_hpc.transient.imex import auto_implicit_hexes

    mesh = box_mesh((4, 4, 4), (4.0, 4.0, 4.0))
    top = np.isclose(mesh.points[:, 2], 4.0)
    mesh.points[top, 2] = 3.1                       # the top layer 0.1 m thick
    thin = np.ptp(mesh.points[mesh.hexes][:, :, 2], axis=1) < 0.2
    assert thin.sum() == 16
    case = soil_case("modal.lumped_mass=true", "damping.model=none")
    problem = Problem.from_case(case)
    w = hex_max_frequencies(mesh, problem)
    steps = 0.9 * 2.0 / w
    target = np.sqrt(steps[thin].max() * steps[~thin].min())
    assert np.array_equal(auto_implicit_hexes(mesh, problem, target, 0.9, share=0.5), thin)
    capped = auto_implicit_hexes(mesh, problem, target, 0.9, share=0.1)
    assert capped.sum() <= 0.1 * len(w) + 1 and not (capped & ~thin).any()
    from scipy.linalg import eigh

    from railvib_hpc.model.dofmap import build_dofmap
    from railvib_hpc.model.petsc import assemble

    K, M, _ = assemble(mesh, Problem.from_case(case), build_dofmap(mesh, 1, rules=RULES),
                       MPI.COMM_SELF)
    lam = eigh(K.convert("dense").getDenseArray(), M.convert("dense").getDenseArray(),
               eigvals_only=True).max()
    K.destroy()
    M.destroy()
    assert math.sqrt(lam) <= w.max() * (1 + 1e-9)
    assert math.sqrt(lam) > 0.5 * w.max()


def test_rail_columns_keep_only_their_support_on_the_imex_engine(tmp_path):
    """On the IMEX engine a rail column of K_eff^-1 is nonzero on the implicit rows the
    rail reaches only (the explicit rows are diagonal and uncoupled): the columns keep
    those rows, and ``apply`` and ``block`` give the dense columns' values.
    Before, every column was held on all rows (a run grew by ~2 MB per step and rank while
    a car entered jobs/real_site.toml)."""
    from transient_cases import tiny_case

    from railvib_hpc.io.stage_protocol import StageContext
    from railvib_hpc.log import Reporter
    from railvib_hpc.petsc_env import init_petsc
    from railvib_hpc.transient.integrate import RailColumns
    from railvib_hpc.transient.stage import _setup

    init_petsc([])
    init = _setup(StageContext(tiny_case("transient.engine=imex", "modal.lumped_mass=true"),
                               tmp_path, MPI.COMM_SELF, Reporter(0)))
    system, rails = init["system"], init["rails"]
    try:
        wheel_rail, elem = np.array([0, 1]), np.array([3, 3])
        dofs = np.stack([np.concatenate([rails.dofs[r, 3], rails.dofs[r, 4]])
                         for r in wheel_rail])
        columns = RailColumns(system, rails, 12)
        columns.require(dofs, wheel_rail, elem)
        rows = {id(r): r for r in columns.rows.values()}
        support = sum(r.size for r in rows.values())
        assert 0 < support < 0.5 * system.n_local * len(rows)
        d = np.unique(dofs[dofs >= 0])
        rhs = np.zeros((system.n_local, d.size))
        rhs[d - system.r0, np.arange(d.size)] = 1.0
        dense = system.solve_block(rhs)
        weights = np.linspace(-1.0, 2.0, d.size)
        expected = np.zeros(system.n_local)
        for j, w in enumerate(weights):
            expected += w * dense[:, j]
        # off the support the dense columns are exact zeros; on it they agree to the
        # round-off of MUMPS blocks of another composition (integrate.RailColumns)
        kept = np.zeros(system.n_local, bool)
        for r in rows.values():
            kept[r] = True
        assert not dense[~kept].any()
        scale = np.abs(dense).max()
        got = columns.apply(d, weights)
        assert np.allclose(got, expected, rtol=0, atol=1e-12 * scale * np.abs(weights).sum())
        block = columns.block(d)
        assert np.allclose(block, 0.5 * (dense[d - system.r0] + dense[d - system.r0].T),
                           rtol=0, atol=1e-12 * scale)
    finally:
        init["solver"].destroy()
        system.destroy()
