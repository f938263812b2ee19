"""The divergence guard of the time-domain engines: a run that grows without bound stops.

What is checked: every output stride of steps (widened until the checks cost at most
:data:`GUARD_COST_SHARE` of the integration, at most :data:`MAX_CHECK_INTERVAL` steps
apart) and at the last step, the kinetic energy of the model, ``T_n = 1/2 v_n^T M v_n``
(the lumped ``m`` of the explicit engines), against what the initial state and the loads
can have put in::

    T_n <= GUARD_FACTOR * B_n,   B_n = E_0 + 1/2 dt^2 a_0^T M a_0 + W_n^+,

``E_0 = 1/2 v_0^T M v_0 + 1/2 u_0^T K u_0`` the energy of the initial state (the static
deflection under a vehicle), ``a_0`` its acceleration and ``W_n^+`` the work of the
prescribed and contact loads on the model, summed over the intervals between two checks
with each interval's negative total left out (what the loads can have put in, not what
they took out). The work is taken in each scheme's own energy balance, so that the balance
holds to round-off:

* generalized-alpha (``direct``): ``f_{n+1-alpha_f}^T (u_{n+1} - u_n)``. With ``rho_inf
  = 1`` (the trapezoidal rule) ``E_{n+1} - E_n`` is exactly that less the dashpots' ``dt
  vbar^T C vbar >= 0``; with ``rho_inf < 1`` the scheme also dissipates, except for the
  velocity overshoot of a state not in equilibrium at t = 0 (a load already on at rest),
  which for one oscillator stays below ``(1 - rho_inf)^2 / 16`` of ``1/2 (dt a_0)^2``
  for every ``omega dt`` (Chung & Hulbert 1993's amplification matrix, evaluated in
  ``tests/transient/test_guard.py``): hence the ``a_0`` term;
* central differences (``explicit``) and the IMEX step (a leapfrog of its predictors on
  ``m + beta dt^2 K_I``): ``dt f_n^T v_n``, the exact change of their discrete energy
  ``E_{n+1/2}`` (:meth:`~.explicit.ExplicitSystem.scheme_energy`,
  :meth:`~.imex.ImexSystem.scheme_energy`), which equals ``T_n + 1/2 u_n^T (K - dt^2 / 4
  K m^-1 K) u_n``: ``T_n <= E_{n+1/2}`` exactly while the step is below the stability
  limit ``2 / omega_max``, the bound the pre-check enforces.

Why :data:`GUARD_FACTOR` = 2 and not 1: two energies lie outside these balances, each at
most ``B_n`` itself. (i) The damping force at the half-step velocity (or ``v*`` of the IMEX
engine) leaves a boundary term ``dt / 4 w^T C w`` in the sum of the step dissipations
(:meth:`~.explicit.ExplicitSystem.step_dissipation` telescopes to it), at most the kinetic
energy at the stability limit (``dt / 2 C <= m`` there). (ii) The perfectly matched
layers' memory forces are not in any of the balances; a stable layer gives back at most
the energy that entered it, itself at most ``B_n``. A run that grows without bound passes
any fixed factor within a few periods of its growing mode (the energy grows as
``rho^(2n)``, ``rho > 1`` the spectral radius), so the factor costs little detection time:
``log(2) / log(rho^2)`` steps.

Cost: the kinetic energy needs one pass over this rank's rows (and, for the consistent
mass of the direct engine, one product with M), the work a dot product over the loaded
DOFs per step, and a check one ``Allreduce`` of the energies per region plus one
broadcast of the verdict. Measured per check in :attr:`DivergenceGuard.time`
(the run's last line on the guard gives ns per DOF per check).

Where it grows: every DOF is given the region of its node (the part of its elements,
beams and pads before solids; a perfectly matched layer's elements before both), and the
region with the largest share of the kinetic energy is named, with the node that carries
most of it. The line also says the likely cause and what to change
(:func:`diagnosis`).

Test hook: :data:`TEST_INJECTION` (tests only; the program never sets it) makes the stage
inject an instability after its pre-checks: ``Injection("step", f)`` multiplies the step
of the explicit and IMEX engines by ``f`` past their stability limit, ``Injection(
"negative_damping", f)`` scales the direct engine's damping matrix by ``-f``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..errors import DivergenceError
from ..schema import BEAM_PARTS, PART_ID, PARTS

#: Multiple of the energy bound ``B_n`` at which a run counts as diverged (see the module
#: notes: the balances hold to round-off; the half-step damping term and the layers'
#: memory each add at most ``B_n``).
GUARD_FACTOR = 2.0
#: Most steps between two checks. An energy that grows by ``g`` per step overflows a double
#: (from ~1 J, at 1e308 J) only after ``709 / ln(g)`` steps: at 64 steps a growth of up to
#: 6e4 per step is still seen finite, with its time and place.
MAX_CHECK_INTERVAL = 64
#: Largest share of the integration's time the checks may take: after the first check the
#: interval grows (up to :data:`MAX_CHECK_INTERVAL`) until the measured check costs at most
#: this share of the steps between two checks (the direct engine's consistent mass product
#: took 122 ns per DOF per check against 1.1 us per DOF per step, every 2 steps: 5 %).
GUARD_COST_SHARE = 0.01
#: Region 0: DOFs whose node no element names (never in practice).
OTHER = "other DOFs"


@dataclass(frozen=True)
class Injection:
    """An instability injected after the pre-checks (test hook, :data:`TEST_INJECTION`).

    Attributes
    ----------
    kind
        ``"step"`` (explicit, IMEX: the step times ``factor``) or ``"negative_damping"``
        (direct: C times ``-factor``).
    factor
        The multiplier.
    """

    kind: str
    factor: float


#: The test hook (see the module notes); None in every run of the program.
TEST_INJECTION: Injection | None = None


def node_regions(mesh, layers: list[tuple[str, np.ndarray]]) -> tuple[np.ndarray, list[str]]:
    """Every node's region and the regions' names.

    Parameters
    ----------
    mesh
        The model.
    layers
        ``(face, mask of the hexahedra in its perfectly matched layer)`` per ``pml`` face.

    Returns
    -------
    region, names : ndarray (n_nodes,), list of str
        Region ids (index into ``names``): 0 :data:`OTHER`, ``PART_ID[p]`` part ``p``, then
        one per layer. A node takes the largest part id of its hexahedra, then its line
        elements' (pads, then beams), then its layer's.
    """
    region = np.zeros(mesh.n_nodes, dtype=np.int64)
    if len(mesh.hexes):
        np.maximum.at(region, mesh.hexes.ravel(), np.repeat(mesh.hex_part.astype(np.int64), 8))
    if len(mesh.lines):
        beams = np.isin(mesh.line_part, [PART_ID[p] for p in BEAM_PARTS])
        for sel in (~beams, beams):
            region[mesh.lines[sel].ravel()] = np.repeat(mesh.line_part[sel], 2)
    names = [OTHER, *(f"part {p}" for p in PARTS)]
    for face, inside in layers:
        names.append(f"the perfectly matched layer of boundary.{face}")
        region[mesh.hexes[inside].ravel()] = len(names) - 1
    return region, names


def dof_regions(region: np.ndarray, index: np.ndarray, r0: int, r1: int) -> np.ndarray:
    """The region of each of this rank's rows ``[r0, r1)`` (``index``: the DOF map's
    ``(n_nodes, k)`` global DOF numbers, -1 for none)."""
    dtype = np.uint8 if region.max(initial=0) < 256 else np.int32    # (1 byte per DOF)
    out = np.zeros(r1 - r0, dtype=dtype)
    own = (index >= r0) & (index < r1)
    out[index[own] - r0] = np.broadcast_to(region[:, None], index.shape)[own]
    return out


def sparse_dot(load, r0: int, x: np.ndarray) -> float:
    """``f^T x`` over this rank's rows of a sparse load ``(dofs, values)`` (DOFs < 0 and
    other ranks' rows left out, as :func:`~.integrate.add_sparse` applies it)."""
    if load is None:
        return 0.0
    d = np.asarray(load[0]).ravel()
    v = np.asarray(load[1], dtype=float).ravel()
    own = (d >= r0) & (d < r0 + x.size)
    return float(v[own] @ x[d[own] - r0]) if own.any() else 0.0


def diagnosis(region: str, engine: str, dt: float, allowed: float | None) -> tuple[str, str]:
    """The likely cause of a growth in ``region`` and what to change.

    ``allowed``: the explicit part's stable step (None for the direct engine, which is
    unconditionally stable).
    """
    if region.startswith("the perfectly matched layer of boundary."):
        face = region.rsplit(".", 1)[1]
        return (f"{region} is unstable (a layer that cuts through the embankment, the "
                "track bed, layered soil or the soil beside the building can grow)",
                f"give boundary.{face} = 'absorbing' (or 'caughey'), or move that face away "
                "from those parts (domain.extra_length, domain.extra_width, "
                "domain.extra_depth)")
    if allowed is not None:
        if dt > allowed * (1.0 + 1e-9):
            return (f"the step {dt:.4g} s is above the {engine} engine's stable step "
                    f"{allowed:.4g} s", "lower transient.dt (0: automatic)")
        return (f"the step {dt:.4g} s is at the {engine} engine's estimated stable step "
                f"{allowed:.4g} s, which {region} does not keep",
                f"lower transient.dt to {0.5 * dt:.3g} s or less, or use transient.engine "
                "= 'direct'")
    return (f"the direct engine is unconditionally stable, so the model grows: a negative "
            f"stiffness or damping in {region}",
            "check the materials of that part and the [damping] keys")


class DivergenceGuard:
    """The check of the module notes for one run (collective methods).

    Parameters
    ----------
    system
        The engine's system (``K``, ``r0``, ``r1``, ``comm``; ``m`` for the explicit
        engines, ``M`` and :meth:`vector` for the direct one).
    solver
        The stepping solver: its ``work`` (this rank's load work so far) is read at checks.
    regions, names
        :func:`dof_regions` of this rank's rows and their names (:func:`node_regions`).
    points, index
        ``(n_nodes, 3)`` node coordinates and the DOF map's ``(n_nodes, k)`` global DOF
        numbers, for the line's position (read only when it trips).
    dt, engine, allowed
        Step, ``transient.engine``, the explicit part's stable step (None: direct).
    interval
        Steps between two checks at first (the output stride; at most
        :data:`MAX_CHECK_INTERVAL`, widened after the first check by its cost).
    """

    def __init__(self, system, solver, regions: np.ndarray, names: list[str],
                 points: np.ndarray, index: np.ndarray, dt: float, engine: str,
                 allowed: float | None, interval: int):
        self.system, self.solver, self.comm = system, solver, system.comm
        self.regions, self.names = regions, names
        self.points, self.index = points, index
        self.dt, self.engine, self.allowed = float(dt), engine, allowed
        self.interval = max(1, min(int(interval), MAX_CHECK_INTERVAL))
        self._t_started = time.perf_counter()
        self._first_step = 0
        self.budget = 0.0
        self.largest_ratio = 0.0
        self.n_checks = 0
        self.time = 0.0
        self._work_seen = 0.0
        self._last_check = 0

    # ---------------------------------------------------------------- products
    def _mass_times(self, v: np.ndarray) -> np.ndarray:
        sys_ = self.system
        if getattr(sys_, "m", None) is not None:
            return sys_.m * v
        return self._product(sys_.M, v)

    def _product(self, A, x: np.ndarray) -> np.ndarray:
        sys_ = self.system
        if hasattr(sys_, "times"):               # the explicit engines' systems
            return sys_.times(A, x)
        src, out = sys_.vector(np.ascontiguousarray(x, dtype=float).copy()), sys_.vector()
        A.mult(src, out)
        result = sys_.local(out).copy()
        src.destroy()
        out.destroy()
        return result

    # ---------------------------------------------------------------- the check
    def start(self, state) -> None:
        """The bound's start ``E_0 + 1/2 dt^2 a_0^T M a_0`` from the initial (or resumed)
        state (collective)."""
        t0 = time.perf_counter()
        u, v, a = state.u, state.v, state.a
        local = (0.5 * float(v @ self._mass_times(v)) + 0.5 * float(u @ self._product(
            self.system.K, u)) + 0.5 * self.dt ** 2 * float(a @ self._mass_times(a)))
        self.budget = max(self.comm.allreduce(local), 0.0)
        self._work_seen = self.solver.work
        self._last_check = self._first_step = state.step
        self.time += time.perf_counter() - t0
        self._t_started = time.perf_counter()

    def due(self, step: int, last: bool) -> bool:
        """Whether step ``step`` is checked: :attr:`interval` steps after the previous
        check (the output stride, widened by :meth:`_calibrate`), and the last step."""
        return last or step - self._last_check >= self.interval

    def _calibrate(self, step: int, t_check: float) -> None:
        """After the first check: widen :attr:`interval` so that a check costs at most
        :data:`GUARD_COST_SHARE` of the steps between two (rank 0 measures, every rank takes
        its value: the ranks check at the same steps; the numbers never depend on it)."""
        steps = step - self._first_step
        if steps <= 0:
            return
        per_step = max(time.perf_counter() - self._t_started - t_check, 1e-12) / steps
        want = math.ceil(t_check / (GUARD_COST_SHARE * per_step))
        interval = max(self.interval, min(want, MAX_CHECK_INTERVAL))
        self.interval = self.comm.bcast(interval, root=0) if self.comm.size > 1 else interval

    def check(self, state) -> None:
        """Raise :class:`~railvib_hpc.errors.DivergenceError` on every rank when the
        kinetic energy passes :data:`GUARD_FACTOR` times the bound (or is not finite)."""
        from mpi4py import MPI

        t0 = time.perf_counter()
        v = state.v
        density = 0.5 * v * self._mass_times(v)
        finite = np.isfinite(density)
        n = len(self.names)
        local = np.zeros(2 * n + 1)
        local[:n] = np.bincount(self.regions[finite], weights=density[finite], minlength=n)
        local[n:2 * n] = np.bincount(self.regions[~finite], minlength=n)
        local[2 * n] = self.solver.work - self._work_seen
        total = local.copy()
        if self.comm.size > 1:
            self.comm.Allreduce(MPI.IN_PLACE, total, op=MPI.SUM)
        self._work_seen = self.solver.work
        self.budget += max(total[2 * n], 0.0)
        kinetic, bad = float(total[:n].sum()), int(total[n:2 * n].sum())
        ratio = (math.inf if bad or (kinetic > 0.0 and self.budget <= 0.0)
                 else kinetic / self.budget if kinetic > 0.0 else 0.0)
        tripped = ratio > GUARD_FACTOR
        if self.comm.size > 1:              # one verdict for all ranks (rank 0's)
            tripped = self.comm.bcast(tripped, root=0)
        self.n_checks += 1
        self._last_check = state.step
        self.largest_ratio = max(self.largest_ratio, ratio if np.isfinite(ratio) else 0.0)
        self.time += time.perf_counter() - t0
        if self.n_checks == 1 and not tripped:
            self._calibrate(state.step, time.perf_counter() - t0)
        if tripped:
            shares = total[n:2 * n] if bad else total[:n]
            raise DivergenceError(self._line(state.step, ratio, kinetic, bad, shares,
                                             density, finite))

    def _line(self, step: int, ratio: float, kinetic: float, bad: int, shares: np.ndarray,
              density: np.ndarray, finite: np.ndarray) -> str:
        """The one line (collective: the position is gathered)."""
        k = int(np.argmax(shares))
        region = self.names[k]
        share = shares[k] / max(shares.sum(), 1e-300)
        score = np.where(finite, density, np.inf)
        here = (-1.0, -1)
        if score.size:
            row = self.system.r0 + int(np.argmax(score))
            here = (float(score.max()), int(np.argwhere(self.index == row)[0, 0]))
        _, node = max(self.comm.allgather(here))
        where = (f", largest at x = {self.points[node, 0]:.2f}, y = "
                 f"{self.points[node, 1]:.2f}, z = {self.points[node, 2]:.2f} m"
                 if node >= 0 else "")
        t = step * self.dt
        if bad:
            growth = (f"{bad} velocities are no longer finite (the energy overflowed since "
                      f"t = {self._previous_time(step):.4g} s)")
            what = "of the non-finite values"
        elif self.budget <= 0.0:
            growth = (f"the kinetic energy is {kinetic:.3g} J where the initial state and the "
                      "loads have put in nothing (0 J)")
            what = "of it"
        else:
            growth = (f"the kinetic energy {kinetic:.3g} J is {ratio:.3g} x what the initial "
                      f"state and the loads can have put in ({self.budget:.3g} J; allowed: "
                      f"{GUARD_FACTOR:g} x)")
            what = "of it"
        cause, change = diagnosis(region, self.engine, self.dt, self.allowed)
        return (f"the time integration diverged at t = {t:.4f} s: {growth}; it grows in "
                f"{region} ({100 * share:.0f} % {what}{where}); likely cause: {cause}; "
                f"change: {change}; nothing was written as a result")

    @property
    def last_check_time(self) -> float:
        """The time of the last check (or of the start) [s]."""
        return self._last_check * self.dt

    def _previous_time(self, step: int) -> float:
        return max(step - self.interval, 0) * self.dt

    def summary(self, n_dofs: int) -> str:
        """One line on the checks: how many, how often, the largest ratio, the cost."""
        per = 1e9 * self.time / max(self.n_checks, 1) / max(n_dofs, 1)
        return (f"  divergence guard: {self.n_checks} checks (every {self.interval} steps at "
                f"most), largest kinetic energy {self.largest_ratio:.3g} x its bound (stops at "
                f"{GUARD_FACTOR:g} x), {per:.3g} ns per DOF per check")

    def stats(self, n_dofs: int) -> dict:
        """The guard's numbers for the run statistics."""
        return {"checks": self.n_checks, "interval_steps": self.interval,
                "largest_ratio": self.largest_ratio, "factor": GUARD_FACTOR,
                "ns_per_dof_check": 1e9 * self.time / max(self.n_checks, 1)
                / max(n_dofs, 1)}


__all__ = ["GUARD_COST_SHARE", "GUARD_FACTOR", "MAX_CHECK_INTERVAL", "TEST_INJECTION",
           "DivergenceGuard", "Injection", "diagnosis", "dof_regions", "node_regions",
           "sparse_dot"]
