"""Four-axle rail vehicles (car body, two bogies, four wheelsets) and trains of them.

Vertical-plane dynamics with roll, linear suspensions; same interface as
:class:`~.vehicles.SuspendedWheelset` (mass, damping and stiffness matrices,
contact matrix ``B``, constant external force, Hertz data, static wheel
loads, energy), so :func:`~.vehicles.static_equilibrium` and the integrators
can use it, plus the wheel layout ``wheel_offsets`` / ``wheel_rail``.

Coordinates and signs
---------------------
The vehicle runs towards +x; "front"/"leading" is the +x end. Every body has
a vertical displacement ``z`` (up positive, from the position of zero
penetration on the undeformed rail at zero suspension deflection, i.e. the
springs are unstressed at ``y = 0`` and gravity is the external force).
Pitch ``phi`` is positive nose up: a point at longitudinal distance ``xi``
(positive forwards) from the body's reference point moves up by ``phi xi``.
Roll ``theta`` is positive when it raises the side at lateral position
``+contact_span/2`` (rail 0): a point at lateral position ``y`` moves up by
``theta y`` (the convention of :class:`~.vehicles.SuspendedWheelset`). The
centres of gravity lie on the reference points, so gravity produces no
moments.

DOF order of :class:`RailVehicle` (17): car body ``z, pitch, roll``; front
bogie ``z, pitch, roll``; rear bogie ``z, pitch, roll``; wheelsets 0-3 (front
to rear) ``z, roll``. Wheels (8): wheelset by wheelset, leading first; in each
wheelset first the wheel on rail 0 (``+contact_span/2``) then rail 1.

Suspension: per axle box side a primary spring + damper at lateral
``+-primary_span/2`` between the wheelset and the bogie frame at the axle
position (``+-semi_wheelbase`` from the bogie centre); per bogie side a
secondary spring + damper at ``+-secondary_span/2`` between the bogie centre
and the car body at ``+-bogie_semi_spacing`` from the car centre; per bogie an
anti-roll bar, a torsion spring ``k_antiroll`` on the relative roll of car body
and bogie frame. Each spring of stiffness ``k`` adds ``k g g^T`` to K where
``g . y`` is the relative displacement (or rotation) of its two ends.

Default data: the Manchester Benchmark passenger vehicle ("vehicle 1";
S. Iwnicki, "Manchester benchmarks for rail vehicle simulation", Vehicle
System Dynamics 30 (1998) 295-313; also in Iwnicki (ed.), *Handbook of
Railway Vehicle Dynamics*, CRC 2006): car body 32,000 kg, Iyy 1.97e6 kg m^2,
Ixx 5.68e4 kg m^2; bogie frame 2,615 kg, Iyy 1,476 kg m^2, Ixx 1,722 kg m^2;
wheelset 1,813 kg, Ixx 1,120 kg m^2; primary vertical stiffness 1.22 MN/m and
damping 4 kN s/m per axle box; secondary vertical stiffness 0.43 MN/m and
damping 20 kN s/m per side; anti-roll bar 940 kN m/rad per bogie; bogie centre
spacing 19 m, wheelbase 2.56 m, wheel radius 0.46 m, contact span 1.5 m;
lateral spacing of the primary and of the secondary springs 2.0 m. The primary
vertical stiffness is 1.22 MN/m in Iwnicki's table; the open TTB-2D toolbox
(github.com/DanielCanteroNTNU/TTB-2D, ``TrainProp_Manchester_BenchMark.m``)
uses 1.20 MN/m: 1.6 % softer, 0.8 % lower bogie bounce frequency. The car
length over couplers (26.4 m) is not
part of the benchmark: it is the length of a UIC-Z type coach with the same
19 m bogie spacing, and only sets the wheel offsets in a :class:`Train` and
the coupler positions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..constants import STANDARD_GRAVITY
from .contact import jenkins_hertz_constant
from .vehicles import LinearVehicle

_BODY_NAMES = ("body.z", "body.pitch", "body.roll")


def _block_diag(mats: Sequence[np.ndarray]) -> np.ndarray:
    n = sum(m.shape[0] for m in mats)
    p = sum(m.shape[1] for m in mats)
    out = np.zeros((n, p))
    i = j = 0
    for m in mats:
        out[i:i + m.shape[0], j:j + m.shape[1]] = m
        i, j = i + m.shape[0], j + m.shape[1]
    return out


class _LinearVehicle(LinearVehicle):
    """Shared methods of linear vehicles with Hertz wheel contacts."""

    def sparse_stiffness(self):
        """The stiffness matrix as a scipy sparse matrix (a train's is block diagonal)."""
        import scipy.sparse as sp

        return sp.csr_matrix(self.stiffness_matrix())

    def sparse_contact(self):
        """The contact matrix B as a scipy sparse matrix."""
        import scipy.sparse as sp

        return sp.csr_matrix(self.contact_matrix())

    def static_wheel_loads(self) -> np.ndarray:
        """(n_wheels,) wheel loads on a rigid, level rail [N].

        Linear solve of ``K y = f_ext + B F`` with rigid contacts ``B^T y = 0``, sparse
        (SuperLU on the saddle-point system): a train's matrices are block diagonal, so
        the work grows with its length, where the dense solve grew with its cube (1000
        cars: 17,000 DOFs, about 6 min and 5 GB dense).
        For a symmetric four-axle car every wheel carries
        ``(m_car / 8 + m_bogie / 4 + m_wheelset / 2) g`` (lever rule).
        """
        import scipy.sparse as sp
        from scipy.sparse.linalg import spsolve

        k, b, f = self.sparse_stiffness(), self.sparse_contact(), self.external_force()
        nd, nw = b.shape
        a = sp.bmat([[k, -b], [b.T, sp.csr_matrix((nw, nw))]], format="csc")
        return np.atleast_1d(spsolve(a, np.concatenate([f, np.zeros(nw)])))[nd:]


@dataclass(frozen=True)
class RailVehicle(_LinearVehicle):
    """Four-axle vehicle: car body, two bogies, four wheelsets (17 DOFs, 8 wheels).

    See the module notes for coordinates, DOF/wheel order and the default
    data (Manchester Benchmark vehicle).

    Parameters
    ----------
    car_mass, car_pitch_inertia, car_roll_inertia
        Car body mass [kg] and moments of inertia about the lateral (pitch)
        and longitudinal (roll) axes [kg m^2].
    bogie_mass, bogie_pitch_inertia, bogie_roll_inertia
        Per bogie frame [kg], [kg m^2].
    wheelset_mass, wheelset_roll_inertia
        Per wheelset [kg], [kg m^2].
    bogie_semi_spacing
        Half the distance between the bogie centres [m].
    semi_wheelbase
        Half the bogie wheelbase [m].
    car_length
        Length over couplers [m], centred on the car body's reference point.
    wheel_radius
        Rolling radius [m] (Jenkins' Hertz constant unless ``k_hertz`` is given).
    contact_span
        Lateral distance between the two wheel-rail contact points [m].
    primary_span, secondary_span
        Lateral distance between the primary (axle box) springs and between
        the secondary springs [m].
    k_primary, c_primary
        Primary vertical stiffness [N/m] and damping [N s/m] per axle box.
    k_secondary, c_secondary
        Secondary vertical stiffness [N/m] and damping [N s/m] per bogie side.
    k_antiroll
        Anti-roll bar stiffness per bogie [N m/rad]: roll moment between the car body
        and the bogie frame per radian of relative roll.
    contact_damping
        Hertz contact damping ``C`` [N s/m^2] (see :mod:`.contact`).
    gravity
        Gravitational acceleration [m/s^2] (standard gravity by default).
    k_hertz
        Hertz constant [N/m^1.5]; None for Jenkins' formula.
    """

    car_mass: float = 32_000.0
    car_pitch_inertia: float = 1.97e6
    car_roll_inertia: float = 5.68e4
    bogie_mass: float = 2_615.0
    bogie_pitch_inertia: float = 1_476.0
    bogie_roll_inertia: float = 1_722.0
    wheelset_mass: float = 1_813.0
    wheelset_roll_inertia: float = 1_120.0
    bogie_semi_spacing: float = 9.5
    semi_wheelbase: float = 1.28
    car_length: float = 26.4
    wheel_radius: float = 0.46
    contact_span: float = 1.5
    primary_span: float = 2.0
    secondary_span: float = 2.0
    k_primary: float = 1.22e6
    c_primary: float = 4.0e3
    k_secondary: float = 0.43e6
    c_secondary: float = 2.0e4
    k_antiroll: float = 940e3
    contact_damping: float = 0.0
    gravity: float = STANDARD_GRAVITY
    k_hertz: float | None = None

    n_dof = 17
    n_wheels = 8
    #: Vertical model: the contact normals are vertical (no tread conicity).
    conicity = 0.0
    dof_names = (_BODY_NAMES
                 + tuple(f"bogie{i}.{d}" for i in range(2) for d in ("z", "pitch", "roll"))
                 + tuple(f"wheelset{i}.{d}" for i in range(4) for d in ("z", "roll")))

    def __post_init__(self) -> None:
        positive = ("car_mass", "car_pitch_inertia", "car_roll_inertia", "bogie_mass",
                    "bogie_pitch_inertia", "bogie_roll_inertia", "wheelset_mass",
                    "wheelset_roll_inertia", "semi_wheelbase", "wheel_radius", "contact_span",
                    "primary_span", "secondary_span", "k_primary", "k_secondary")
        for name in positive:
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)!r}")
        for name in ("c_primary", "c_secondary", "k_antiroll", "contact_damping"):
            if not getattr(self, name) >= 0.0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not self.bogie_semi_spacing > self.semi_wheelbase:
            raise ValueError("bogie_semi_spacing must exceed semi_wheelbase (bogies overlap)")
        if self.front_overhang < 0.0:
            base = 2.0 * (self.bogie_semi_spacing + self.semi_wheelbase)
            raise ValueError(f"car_length {self.car_length!r} is shorter than the distance "
                             f"between the outer axles {base!r}")

    # --- geometry -------------------------------------------------------------------
    @property
    def front_overhang(self) -> float:
        """Distance from the front end (coupler) to the leading wheelset [m]."""
        return 0.5 * self.car_length - self.bogie_semi_spacing - self.semi_wheelbase

    @property
    def wheelset_positions(self) -> np.ndarray:
        """(4,) longitudinal positions of the wheelsets from the car centre [m] (front first)."""
        lc, lt = self.bogie_semi_spacing, self.semi_wheelbase
        return np.array([lc + lt, lc - lt, -lc + lt, -lc - lt])

    @property
    def wheel_offsets(self) -> np.ndarray:
        """(8,) x offset of each wheel from the leading wheel [m] (0 or negative)."""
        p = self.wheelset_positions
        return np.repeat(p - p[0], 2)

    @property
    def wheel_rail(self) -> np.ndarray:
        """(8,) rail index of each wheel (0 at ``+contact_span/2``, 1 at ``-contact_span/2``)."""
        return np.tile([0, 1], 4)

    @property
    def total_mass(self) -> float:
        """Mass of the whole vehicle [kg]."""
        return self.car_mass + 2.0 * self.bogie_mass + 4.0 * self.wheelset_mass

    @property
    def hertz_constant(self) -> float:
        """Hertz constant ``K_H`` used at all wheels [N/m^1.5]."""
        return self.k_hertz if self.k_hertz is not None else jenkins_hertz_constant(
            self.wheel_radius)

    # --- matrices -------------------------------------------------------------------
    def _spring_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """Relative-displacement rows ``g`` of the (8,) primary and (4,) secondary springs."""
        lc, lt = self.bogie_semi_spacing, self.semi_wheelbase
        gp = np.zeros((8, 17))
        for w in range(4):
            b = w // 2
            xi = lt if w % 2 == 0 else -lt  # axle position relative to its bogie centre
            for s, y in enumerate((0.5 * self.primary_span, -0.5 * self.primary_span)):
                g = gp[2 * w + s]
                g[9 + 2 * w], g[10 + 2 * w] = 1.0, y  # wheelset z, roll
                g[3 + 3 * b], g[4 + 3 * b], g[5 + 3 * b] = -1.0, -xi, -y  # bogie z, pitch, roll
        gs = np.zeros((4, 17))
        for b in range(2):
            xi = lc if b == 0 else -lc
            for s, y in enumerate((0.5 * self.secondary_span, -0.5 * self.secondary_span)):
                g = gs[2 * b + s]
                g[3 + 3 * b], g[5 + 3 * b] = 1.0, y  # bogie centre z, roll
                g[0], g[1], g[2] = -1.0, -xi, -y  # car body z, pitch, roll
        return gp, gs

    def _antiroll_rows(self) -> np.ndarray:
        """Relative-roll rows of the (2,) anti-roll bars: bogie roll minus car body roll."""
        g = np.zeros((2, 17))
        for b in range(2):
            g[b, 5 + 3 * b], g[b, 2] = 1.0, -1.0
        return g

    def _suspension_matrix(self, kp: float, ks: float, k_roll: float = 0.0) -> np.ndarray:
        gp, gs = self._spring_rows()
        a = kp * gp.T @ gp + ks * gs.T @ gs
        if k_roll:
            gr = self._antiroll_rows()
            a = a + k_roll * gr.T @ gr
        return 0.5 * (a + a.T)  # exactly symmetric

    def mass_matrix(self) -> np.ndarray:
        """(17, 17) diagonal mass matrix."""
        bogie = [self.bogie_mass, self.bogie_pitch_inertia, self.bogie_roll_inertia]
        wheelset = [self.wheelset_mass, self.wheelset_roll_inertia]
        return np.diag([self.car_mass, self.car_pitch_inertia, self.car_roll_inertia]
                       + 2 * bogie + 4 * wheelset)

    def stiffness_matrix(self) -> np.ndarray:
        """(17, 17) suspension stiffness matrix.

        Singular with 5 zero-energy modes while the wheels are free: bounce,
        pitch and roll of the whole vehicle, and the pitch of each bogie with
        its two wheelsets moving up/down with the axle boxes (the secondary
        springs act at the bogie centre).
        """
        return self._suspension_matrix(self.k_primary, self.k_secondary, self.k_antiroll)

    def roll_stiffness(self) -> float:
        """Static roll stiffness of the car body on rigid wheelsets [N m/rad].

        Per bogie the secondary springs (``k_s (s_s/2)^2`` per side) and the anti-roll bar
        act in parallel, in series with the primary springs of both axles
        (``k_p (s_p/2)^2`` per axle box); the two bogies act in parallel.
        """
        secondary = 2.0 * self.k_secondary * (0.5 * self.secondary_span) ** 2 + self.k_antiroll
        primary = 4.0 * self.k_primary * (0.5 * self.primary_span) ** 2
        return 2.0 / (1.0 / secondary + 1.0 / primary)

    def damping_matrix(self) -> np.ndarray:
        """(17, 17) suspension damping matrix."""
        return self._suspension_matrix(self.c_primary, self.c_secondary)

    def contact_matrix(self) -> np.ndarray:
        """(17, 8) matrix B: generalised force ``B @ F`` of upward wheel forces F.

        Its transpose maps the DOFs to the wheel heights ``B.T @ y``.
        """
        b = np.zeros((17, 8))
        half = 0.5 * self.contact_span
        for w in range(4):
            b[9 + 2 * w, 2 * w:2 * w + 2] = 1.0
            b[10 + 2 * w, 2 * w:2 * w + 2] = (half, -half)
        return b

    def external_force(self) -> np.ndarray:
        """(17,) constant generalised force: gravity on the vertical DOFs."""
        f = np.zeros(17)
        f[0] = -self.car_mass
        f[[3, 6]] = -self.bogie_mass
        f[9::2] = -self.wheelset_mass
        return self.gravity * f


class Train(_LinearVehicle):
    """Several :class:`RailVehicle` in a row, optionally coupled vertically.

    The matrices are block diagonal (vehicle 0 first, each with its own DOF
    order) plus, for every pair of adjacent cars, a vertical coupler spring
    ``k_coupler`` and damper ``c_coupler`` between the rear end of the car
    body in front (``-car_length/2`` from its centre) and the front end of the
    car body behind (``+car_length/2``). The default ``k_coupler = c_coupler =
    0`` leaves the car bodies vertically independent, the usual assumption in
    vertical vehicle-track interaction models (the coupler transmits mainly
    longitudinal forces).

    Parameters
    ----------
    vehicles
        The cars, front first. All must share the Hertz constant, contact
        damping and gravity (the integrators use one value for all wheels).
    gaps
        Extra distance between the coupler ends of adjacent cars [m] (scalar or
        one per pair; 0: ``car_length`` is the length over couplers).
    k_coupler, c_coupler
        Vertical coupler stiffness [N/m] and damping [N s/m].
    """

    #: Vertical model: the contact normals are vertical (no tread conicity).
    conicity = 0.0

    def __init__(self, vehicles: Sequence[RailVehicle], gaps: float | Sequence[float] = 0.0,
                 k_coupler: float = 0.0, c_coupler: float = 0.0):
        self.vehicles = tuple(vehicles)
        if not self.vehicles:
            raise ValueError("a train needs at least one vehicle")
        v0 = self.vehicles[0]
        for i, v in enumerate(self.vehicles[1:], start=1):
            if not np.isclose(v.hertz_constant, v0.hertz_constant, rtol=1e-12, atol=0.0):
                raise ValueError(f"vehicle {i} has a different Hertz constant "
                                 f"({v.hertz_constant:.6g} vs {v0.hertz_constant:.6g} N/m^1.5)")
            if v.contact_damping != v0.contact_damping or v.gravity != v0.gravity:
                raise ValueError(f"vehicle {i} has a different contact_damping or gravity")
        n_pairs = len(self.vehicles) - 1
        g = np.broadcast_to(np.asarray(gaps, dtype=float), (n_pairs,)).copy()
        if np.any(g < 0.0) or not np.all(np.isfinite(g)):
            raise ValueError(f"gaps must be finite and >= 0, got {gaps!r}")
        if not (k_coupler >= 0.0 and c_coupler >= 0.0):
            raise ValueError("k_coupler and c_coupler must be >= 0")
        self.gaps = g
        self.k_coupler, self.c_coupler = float(k_coupler), float(c_coupler)
        self.contact_damping = v0.contact_damping
        self.gravity = v0.gravity
        self._hertz = v0.hertz_constant
        self._dof_start = np.concatenate([[0], np.cumsum([v.n_dof for v in self.vehicles])])

    @property
    def n_dof(self) -> int:
        """Total number of DOFs."""
        return int(self._dof_start[-1])

    @property
    def n_wheels(self) -> int:
        """Total number of wheels."""
        return sum(v.n_wheels for v in self.vehicles)

    @property
    def dof_names(self) -> tuple[str, ...]:
        """DOF names ``car<i>.<name>``."""
        return tuple(f"car{i}.{n}" for i, v in enumerate(self.vehicles) for n in v.dof_names)

    @property
    def hertz_constant(self) -> float:
        """Hertz constant ``K_H`` shared by all wheels [N/m^1.5]."""
        return self._hertz

    @property
    def dof_start(self) -> np.ndarray:
        """(n_vehicles + 1,) index of the first DOF of each vehicle (and the total)."""
        return self._dof_start.copy()

    @property
    def wheel_offsets(self) -> np.ndarray:
        """(n_wheels,) x offset of each wheel from the train's leading wheel [m]."""
        out, front = [], self.vehicles[0].front_overhang  # front end of car 0 at +overhang
        for i, v in enumerate(self.vehicles):
            out.append(front - v.front_overhang + v.wheel_offsets)
            if i < len(self.gaps):
                front -= v.car_length + self.gaps[i]
        return np.concatenate(out)

    @property
    def wheel_rail(self) -> np.ndarray:
        """(n_wheels,) rail index of each wheel."""
        return np.concatenate([v.wheel_rail for v in self.vehicles])

    @property
    def total_mass(self) -> float:
        """Mass of the whole train [kg]."""
        return sum(v.total_mass for v in self.vehicles)

    def sparse_stiffness(self):
        """The suspension + coupler stiffness as a sparse matrix (no dense copy)."""
        import scipy.sparse as sp

        k = sp.block_diag([sp.csr_matrix(v.stiffness_matrix()) for v in self.vehicles],
                          format="csr")
        if self.k_coupler and len(self.gaps):
            g = sp.csr_matrix(self._coupler_rows())
            k = k + self.k_coupler * (g.T @ g)
        return k

    def sparse_contact(self):
        """The block-diagonal contact matrix B as a sparse matrix."""
        import scipy.sparse as sp

        return sp.block_diag([sp.csr_matrix(v.contact_matrix()) for v in self.vehicles],
                             format="csr")

    def _coupler_rows(self) -> np.ndarray:
        rows = np.zeros((len(self.gaps), self.n_dof))
        for i in range(len(self.gaps)):
            a, b = self._dof_start[i], self._dof_start[i + 1]  # body z, pitch come first
            rows[i, a], rows[i, a + 1] = 1.0, -0.5 * self.vehicles[i].car_length
            rows[i, b], rows[i, b + 1] = -1.0, -0.5 * self.vehicles[i + 1].car_length
        return rows

    def _assemble(self, blocks: list[np.ndarray], coupler: float) -> np.ndarray:
        g = self._coupler_rows()
        c = coupler * g.T @ g
        return _block_diag(blocks) + 0.5 * (c + c.T)

    def mass_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) block-diagonal mass matrix."""
        return _block_diag([v.mass_matrix() for v in self.vehicles])

    def stiffness_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) suspension + coupler stiffness matrix."""
        return self._assemble([v.stiffness_matrix() for v in self.vehicles], self.k_coupler)

    def damping_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) suspension + coupler damping matrix."""
        return self._assemble([v.damping_matrix() for v in self.vehicles], self.c_coupler)

    def contact_matrix(self) -> np.ndarray:
        """(n_dof, n_wheels) block-diagonal contact matrix B."""
        return _block_diag([v.contact_matrix() for v in self.vehicles])

    def external_force(self) -> np.ndarray:
        """(n_dof,) gravity."""
        return np.concatenate([v.external_force() for v in self.vehicles])


class Traffic(LinearVehicle):
    """Independent trains on their own tracks in one simulation: they interact only through
    the track and the ground (the modal coordinates they share).

    The matrices are block diagonal (train 0 first, no coupling). Each train keeps its own
    wheel layout; ``positions`` places its wheels at t = 0 relative to the simulation's
    reference ``x0`` (so they may lie ahead of or behind the model: a wheel off the flexible
    rail rides on rigid ground), ``speeds`` gives each train's velocity along x (negative:
    running towards -x), ``rail_shift`` moves its wheels to the rails of its own track (2
    for the second track: rails 2 and 3).

    Parameters
    ----------
    trains
        The trains (any :class:`~railvib_hpc.mbs.vehicles.Vehicle`). They must share the
        Hertz constant, contact damping and conicity (the integrators use one value for all
        wheels).
    positions
        Per train, (n_wheels,) wheel positions at t = 0 relative to ``x0`` [m].
    speeds
        Per train, its velocity along x [m/s].
    rail_shift
        Per train, added to its wheels' rail indices.

    Examples
    --------
    Two thesis wheelsets, the second on track 2 running the other way:

    >>> from railvib_hpc.mbs import SuspendedWheelset
    >>> w = SuspendedWheelset(mass=1568.0, roll_inertia=656.0, wheel_radius=0.46,
    ...                       contact_span=1.5, suspension_span=2.0, k_suspension=25e3,
    ...                       c_suspension=1e3)
    >>> both = Traffic([w, w], positions=[[0.0, 0.0], [30.0, 30.0]], speeds=[30.0, -30.0],
    ...                rail_shift=[0, 2])
    >>> both.n_dof, both.n_wheels, both.wheel_rail.tolist(), both.wheel_speeds.tolist()
    (4, 4, [0, 1, 2, 3], [30.0, 30.0, -30.0, -30.0])
    """

    def __init__(self, trains: Sequence, positions: Sequence[Sequence[float]],
                 speeds: Sequence[float], rail_shift: Sequence[int]):
        self.trains = tuple(trains)
        if not (len(self.trains) == len(positions) == len(speeds) == len(rail_shift) >= 1):
            raise ValueError("one position list, speed and rail shift per train")
        t0 = self.trains[0]
        for i, v in enumerate(self.trains[1:], start=1):
            if not np.isclose(v.hertz_constant, t0.hertz_constant, rtol=1e-12, atol=0.0) or \
                    v.contact_damping != t0.contact_damping or v.conicity != t0.conicity:
                raise ValueError(f"train {i} has a different Hertz constant, contact damping "
                                 "or conicity than train 0")
        self._positions = np.concatenate([np.asarray(p, dtype=float) for p in positions])
        self._speeds = np.concatenate([np.full(v.n_wheels, float(s))
                                       for v, s in zip(self.trains, speeds)])
        self._rails = np.concatenate([np.asarray(v.wheel_rail, dtype=np.int64) + int(r)
                                      for v, r in zip(self.trains, rail_shift)])
        if self._positions.size != self._rails.size:
            raise ValueError("each train needs one position per wheel")
        self.conicity = t0.conicity
        self.contact_damping = t0.contact_damping
        self._hertz = t0.hertz_constant
        self._wheel_start = np.concatenate([[0], np.cumsum([v.n_wheels for v in self.trains])])

    @property
    def n_dof(self) -> int:
        """Total number of DOFs."""
        return sum(v.n_dof for v in self.trains)

    @property
    def n_wheels(self) -> int:
        """Total number of wheels."""
        return int(self._wheel_start[-1])

    @property
    def wheel_start(self) -> np.ndarray:
        """(n_trains + 1,) index of the first wheel of each train (and the total)."""
        return self._wheel_start.copy()

    @property
    def dof_names(self) -> tuple[str, ...]:
        """DOF names ``train<i>.<name>``."""
        return tuple(f"train{i}.{n}" for i, v in enumerate(self.trains) for n in v.dof_names)

    @property
    def hertz_constant(self) -> float:
        """Hertz constant ``K_H`` shared by all wheels [N/m^1.5]."""
        return self._hertz

    @property
    def wheel_offsets(self) -> np.ndarray:
        """(n_wheels,) wheel positions at t = 0 relative to ``x0`` [m]."""
        return self._positions.copy()

    @property
    def wheel_speeds(self) -> np.ndarray:
        """(n_wheels,) velocity of each wheel along x [m/s]."""
        return self._speeds.copy()

    @property
    def wheel_rail(self) -> np.ndarray:
        """(n_wheels,) rail index of each wheel."""
        return self._rails.copy()

    def mass_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) block-diagonal mass matrix."""
        return _block_diag([v.mass_matrix() for v in self.trains])

    def stiffness_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) block-diagonal stiffness matrix."""
        return _block_diag([v.stiffness_matrix() for v in self.trains])

    def damping_matrix(self) -> np.ndarray:
        """(n_dof, n_dof) block-diagonal damping matrix."""
        return _block_diag([v.damping_matrix() for v in self.trains])

    def contact_matrix(self) -> np.ndarray:
        """(n_dof, n_wheels) block-diagonal contact matrix B."""
        return _block_diag([v.contact_matrix() for v in self.trains])

    def external_force(self) -> np.ndarray:
        """(n_dof,) gravity and preloads."""
        return np.concatenate([v.external_force() for v in self.trains])

    def static_wheel_loads(self) -> np.ndarray:
        """(n_wheels,) each train's static wheel loads."""
        return np.concatenate([v.static_wheel_loads() for v in self.trains])


__all__ = ["RailVehicle", "Traffic", "Train"]
