"""Vertical rail irregularity (measured or random) and wheel flats.

Conventions
-----------
Heights are the vertical position of the undeformed rail top [m], positive
up, as expected by the ``irregularity`` argument of the integrators. Rail 0
is the rail under the wheels at lateral position ``+contact_span/2``, rail 1
the other one (the convention of :class:`~.vehicles.SuspendedWheelset` and
:class:`~.train.RailVehicle`). A wheel flat lowers the rail height *seen by
that wheel* (it reduces the penetration), so flats and rail irregularity add.

Random profiles (:meth:`RailProfile.from_psd`)
----------------------------------------------
All spectra are *one-sided* displacement PSDs: the variance of the profile
is the integral of the PSD over positive spatial frequencies only.

``"fra"``: US FRA track classes 1-6, vertical profile. Two different spectra circulate
under the name "FRA"; the one implemented is the six-class rational form fitted by the
FRA's track-geometry programme (Hamid, Rasmussen, Baluja & Yang, "Analytical descriptions
of track geometry variations", FRA/ORD-83/03, 1983) in the angular-frequency notation of
Lei & Noda (J. Sound Vib. 258 (2002) 147-165) and Zhai (*Vehicle-Track Coupled Dynamics*,
Springer 2020, ch. 3)::

    S(Omega) = k A_v Omega_c^2 / (Omega^2 (Omega^2 + Omega_c^2))

with ``Omega`` the angular spatial frequency [rad/m], ``A_v`` the roughness
coefficient [cm^2 rad/m], ``Omega_c = 0.8245`` rad/m the cut-off and
``k = 0.25``; ``S`` is then in cm^2/(rad/m). It is a *one-sided* spectrum: the
variance is ``int_0^inf S dOmega`` (tested with the periodogram of generated
profiles). Internally ``A_v`` is converted
to m^2 rad/m (factor 1e-4), so :func:`psd` returns m^2/(rad/m) and profiles
are in metres. Table (class: ``A_v``): 1: 1.2107, 2: 1.0181, 3: 0.6816,
4: 0.5376, 5: 0.2095, 6: 0.0339 (class 6 is the best track). The other
spectrum, ``S(phi) = A phi_2^2 (phi^2 + phi_1^2) / (phi^4 (phi^2 + phi_2^2))`` in
in^2/(cycle/ft) with two break frequencies (Fries & Coffey; Garg & Dukkipati,
*Dynamics of Railway Vehicle Systems*, 1984), is not implemented. Both were fitted to
wavelengths of 5-1000 ft (1.524-304.8 m): the default ``wavelength_min`` is 1.524 m
(a shorter one gives a note). With wavelengths 1-50 m the RMS is 5.7 mm for class 5
and 2.3 mm for class 6.

``"iso8608"``: ISO 8608 (road) style spectrum with fixed waviness ``w = 2``::

    S_d(n) = S_d(n0) (n / n0)^-w,   n0 = 0.1 cycles/m,

``n`` in cycles/m and ``S_d`` in m^2/(cycles/m) = m^3. ``S_d(n0)`` is the ISO
8608 geometric mean of the class: A 16e-6, B 64e-6, C 256e-6, D 1024e-6,
E 4096e-6, F 16384e-6, G 65536e-6, H 262144e-6 m^3. In angular frequency
``S(Omega) = S_d(Omega / 2 pi) / (2 pi)`` (same variance). Note that even
class A is rough for a railway track; the spectrum is offered for comparison
studies with road-type excitation.

Spectral representation: the profile of each rail is
``z(x) = sum_k a_k cos(Omega_k (x - x_0) + phi_k)`` with ``Omega_k = k 2 pi / L``
the harmonics of the generated length ``L``, independent uniform random
phases ``phi_k`` (independent between the two rails: no cross-correlation is
modelled) and ``a_k = sqrt(2 P_k)``, where ``P_k`` is the *exact* integral of
``S`` over the frequency bin ``[Omega_k - dOmega/2, Omega_k + dOmega/2]``
clipped to the band (the midpoint rule ``P_k ~ S(Omega_k) dOmega`` would only
approximate it). Hence ``sum a_k^2 / 2`` equals the band integral of the
spectrum exactly, and because the cosines are harmonics sampled on a uniform
grid over one period, so does the mean square of the sampled profile. The
profile is periodic with period ``L`` (evaluation uses an inverse FFT).
Wavelengths longer than ``L`` are lumped into the fundamental harmonic.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import UserError

#: FRA vertical profile: ``A_v`` [cm^2 rad/m] per class.
FRA_AV: dict[int, float] = {1: 1.2107, 2: 1.0181, 3: 0.6816, 4: 0.5376, 5: 0.2095, 6: 0.0339}
#: FRA vertical profile cut-off wavenumber ``Omega_c`` [rad/m] (all classes).
FRA_OMEGA_C = 0.8245
#: FRA safety/scale factor ``k``.
FRA_K = 0.25
#: ISO 8608 geometric-mean ``S_d(n0)`` [m^3] per class.
ISO8608_SD0: dict[str, float] = {
    c: 16e-6 * 4.0**i for i, c in enumerate("ABCDEFGH")
}
#: ISO 8608 reference spatial frequency ``n0`` [cycles/m] and waviness ``w``.
ISO8608_N0 = 0.1
ISO8608_W = 2.0

KINDS = ("fra", "iso8608")
OUTSIDE = ("zero", "hold", "periodic")


class ProfileFileError(UserError, ValueError):
    """A rail profile file that cannot be read (names the file, line and column)."""


def _check_kind_class(kind: str, track_class: int | str) -> tuple[str, int | str]:
    k = str(kind).lower()
    if k == "fra":
        try:
            c = int(track_class)
        except (TypeError, ValueError):
            c = None
        if c not in FRA_AV or isinstance(track_class, bool | float):
            raise ValueError(f"FRA track class {track_class!r} unknown; allowed: "
                             f"{', '.join(str(i) for i in FRA_AV)}")
        return k, c
    if k == "iso8608":
        c = str(track_class).upper()
        if c not in ISO8608_SD0:
            raise ValueError(f"ISO 8608 class {track_class!r} unknown; allowed: "
                             f"{', '.join(ISO8608_SD0)}")
        return k, c
    raise ValueError(f"spectrum kind {kind!r} unknown; allowed: {', '.join(KINDS)}")


def psd(kind: str, track_class: int | str, omega: np.ndarray | float) -> np.ndarray:
    """One-sided vertical profile PSD in angular spatial frequency.

    Parameters
    ----------
    kind
        ``"fra"`` or ``"iso8608"`` (see the module notes).
    track_class
        FRA class 1-6, or ISO 8608 class ``"A"``-``"H"``.
    omega
        Angular spatial frequency ``Omega`` > 0 [rad/m].

    Returns
    -------
    numpy.ndarray
        ``S(Omega)`` [m^2/(rad/m)].
    """
    k, c = _check_kind_class(kind, track_class)
    om = np.asarray(omega, dtype=float)
    if k == "fra":
        wc2 = FRA_OMEGA_C**2
        return FRA_K * FRA_AV[c] * 1e-4 * wc2 / (om**2 * (om**2 + wc2))
    n = om / (2.0 * np.pi)
    return ISO8608_SD0[c] * (n / ISO8608_N0) ** (-ISO8608_W) / (2.0 * np.pi)


def _cumulative(kind: str, track_class: int | str, omega: np.ndarray) -> np.ndarray:
    """An antiderivative of :func:`psd` with respect to ``Omega``."""
    om = np.asarray(omega, dtype=float)
    if kind == "fra":
        wc = FRA_OMEGA_C
        # wc^2 / (W^2 (W^2 + wc^2)) = 1/W^2 - 1/(W^2 + wc^2)
        return FRA_K * FRA_AV[track_class] * 1e-4 * (-1.0 / om - np.arctan(om / wc) / wc)
    # S_d(n0) n0^2 / n^2 / (2 pi) with n = W / 2 pi  ->  integral = -S_d(n0) n0^2 / n
    return -ISO8608_SD0[track_class] * ISO8608_N0**2 * 2.0 * np.pi / om


def band_variance(kind: str, track_class: int | str,
                  wavelength_range: tuple[float, float]) -> float:
    """Exact integral of the PSD between two wavelengths (the profile variance).

    Parameters
    ----------
    kind
        ``"fra"`` or ``"iso8608"``.
    track_class
        FRA class 1-6, or ISO 8608 class ``"A"``-``"H"``.
    wavelength_range
        ``(lambda_min, lambda_max)`` [m].

    Returns
    -------
    float
        Variance [m^2].
    """
    k, c = _check_kind_class(kind, track_class)
    lmin, lmax = _check_wavelengths(wavelength_range)
    lo, hi = _cumulative(k, c, np.array([2.0 * np.pi / lmax, 2.0 * np.pi / lmin]))
    return float(hi - lo)


def _check_wavelengths(wavelength_range: tuple[float, float]) -> tuple[float, float]:
    lmin, lmax = (float(v) for v in wavelength_range)
    if not (0.0 < lmin < lmax < math.inf):
        raise ValueError(f"wavelength_range must satisfy 0 < lambda_min < lambda_max, got "
                         f"{tuple(wavelength_range)!r}")
    return lmin, lmax


def _read_fields(line: str) -> list[str]:
    content = line.split("#", 1)[0].strip()
    if not content:
        return []
    if "," in content:
        return [f.strip() for f in content.split(",")]
    return content.split()


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


class RailProfile:
    """Vertical profile (rail top height) of both rails on a grid, linearly interpolated.

    Parameters
    ----------
    x
        (n,) strictly increasing positions along the track [m], n >= 2.
    z
        (n,) heights used for both rails, or (2, n) heights of rail 0 and rail 1 [m].
    outside
        Height outside ``[x[0], x[-1]]``: ``"zero"`` (smooth rail), ``"hold"``
        (the end values) or ``"periodic"`` (the profile repeats with period
        ``x[-1] - x[0]``; meant for profiles with ``z[..., -1] == z[..., 0]``
        such as those of :meth:`from_psd`).
    """

    def __init__(self, x: np.ndarray, z: np.ndarray, outside: str = "zero"):
        xa = np.array(x, dtype=float)
        za = np.array(z, dtype=float)
        if xa.ndim != 1 or xa.size < 2:
            raise ValueError("x must be a 1-D array with at least 2 points")
        if not np.all(np.isfinite(xa)) or not np.all(np.diff(xa) > 0.0):
            raise ValueError("x must be finite and strictly increasing")
        if za.shape == xa.shape:
            za = np.vstack([za, za])
        if za.shape != (2, xa.size):
            raise ValueError(f"z must have shape ({xa.size},) or (2, {xa.size}), got {za.shape}")
        if not np.all(np.isfinite(za)):
            raise ValueError("z must be finite")
        if outside not in OUTSIDE:
            raise ValueError(f"outside={outside!r} unknown; allowed: {', '.join(OUTSIDE)}")
        xa.flags.writeable = False
        za.flags.writeable = False
        self._x, self._z, self.outside = xa, za, outside
        self._fill = (0.0, 0.0) if outside == "zero" else (None, None)

    @property
    def x(self) -> np.ndarray:
        """(n,) grid positions [m] (read-only)."""
        return self._x

    @property
    def z(self) -> np.ndarray:
        """(2, n) heights of rail 0 and rail 1 [m] (read-only)."""
        return self._z

    def _positions(self, x: np.ndarray) -> np.ndarray:
        if self.outside == "periodic":
            x0 = self._x[0]
            return x0 + np.mod(x - x0, self._x[-1] - x0)
        return x

    def height(self, x: np.ndarray | float, rail: int = 0) -> np.ndarray:
        """Rail top height(s) at position(s) ``x`` on one rail.

        Parameters
        ----------
        x
            Scalar or array of positions [m].
        rail
            0 or 1.

        Returns
        -------
        numpy.ndarray
            Heights [m], same shape as ``x``.
        """
        if rail not in (0, 1):
            raise ValueError(f"rail must be 0 or 1, got {rail!r}")
        xs = self._positions(np.asarray(x, dtype=float))
        left, right = self._fill
        return np.interp(xs, self._x, self._z[rail], left=left, right=right)

    def heights(self, x: np.ndarray | float, rail: np.ndarray | Sequence[int]) -> np.ndarray:
        """Heights at positions ``x`` on the rails ``rail`` (element-wise, vectorised).

        Parameters
        ----------
        x
            (n,) positions [m].
        rail
            (n,) rail index (0/1) of each position.

        Returns
        -------
        numpy.ndarray
            (n,) heights [m].
        """
        xs = self._positions(np.asarray(x, dtype=float))
        left, right = self._fill
        h0 = np.interp(xs, self._x, self._z[0], left=left, right=right)
        h1 = np.interp(xs, self._x, self._z[1], left=left, right=right)
        return np.where(np.asarray(rail) == 0, h0, h1)

    def save(self, path: str | os.PathLike[str]) -> None:
        """Write ``x, z_rail0, z_rail1`` (full precision) readable by :meth:`from_file`.

        Parameters
        ----------
        path
            Output text file.
        """
        data = np.column_stack([self._x, self._z[0], self._z[1]])
        np.savetxt(path, data, fmt="%.17g", delimiter=", ",
                   header="x [m], z_rail0 [m], z_rail1 [m]")

    @classmethod
    def from_file(
        cls, path: str | os.PathLike[str], z_scale: float = 1.0, outside: str = "zero"
    ) -> RailProfile:
        """Read a profile from a text file.

        Format: one point per line, columns ``x, z`` (same profile on both
        rails) or ``x, z_rail0, z_rail1``, separated by commas or whitespace.
        Empty lines and text after ``#`` are ignored; the first data line may
        be a column header when none of its fields is a number. ``x`` [m] must
        be strictly increasing.

        Parameters
        ----------
        path
            Text file.
        z_scale
            Factor applied to the heights (e.g. 1e-3 for a file in mm).
        outside
            See :class:`RailProfile`.

        Returns
        -------
        RailProfile
            The profile.

        Raises
        ------
        ProfileFileError
            (a ``ValueError``) naming the file, line and column of the first problem.
        """
        name = os.fspath(path)
        try:
            with open(name, encoding="utf-8") as fh:
                lines = fh.read().splitlines()
        except (OSError, UnicodeDecodeError) as exc:
            raise ProfileFileError(f"{name}: cannot read the rail profile file: {exc}") from exc
        rows: list[list[float]] = []
        ncol, first_line, prev = 0, 0, None
        for lineno, line in enumerate(lines, start=1):
            fields = _read_fields(line)
            if not fields:
                continue
            if not rows and ncol == 0 and not any(_is_number(f) for f in fields):
                ncol = -1  # header consumed; still waiting for the first data line
                continue
            if len(fields) not in (2, 3):
                raise ProfileFileError(
                    f"{name}, line {lineno}: expected 2 columns (x, z) or 3 columns "
                    f"(x, z_rail0, z_rail1), found {len(fields)}")
            if rows and len(fields) != ncol:
                raise ProfileFileError(
                    f"{name}, line {lineno}: found {len(fields)} columns but line "
                    f"{first_line} has {ncol}")
            names = ("x", "z") if len(fields) == 2 else ("x", "z_rail0", "z_rail1")
            vals = []
            for col, (f, cname) in enumerate(zip(fields, names), start=1):
                try:
                    v = float(f)
                except ValueError:
                    what = "empty field" if not f else f"cannot read {f!r} as a number"
                    raise ProfileFileError(
                        f"{name}, line {lineno}, column {col} ({cname}): {what}") from None
                if not math.isfinite(v):
                    raise ProfileFileError(
                        f"{name}, line {lineno}, column {col} ({cname}): value {f!r} is not "
                        "finite")
                vals.append(v)
            if prev is not None and vals[0] <= prev[0]:
                raise ProfileFileError(
                    f"{name}, line {lineno}, column 1 (x): x = {fields[0]} is not greater than "
                    f"x = {prev[0]!r} on line {prev[1]}; x must be strictly increasing")
            if not rows:
                ncol, first_line = len(fields), lineno
            rows.append(vals)
            prev = (vals[0], lineno)
        if len(rows) < 2:
            raise ProfileFileError(f"{name}: a rail profile needs at least 2 data lines, "
                                   f"found {len(rows)}")
        data = np.array(rows)
        z = data[:, 1] if ncol == 2 else data[:, 1:].T
        return cls(data[:, 0], z_scale * z, outside=outside)

    @classmethod
    def from_psd(
        cls, kind: str, track_class: int | str, x_range: tuple[float, float], seed: int,
        wavelength_range: tuple[float, float] = (1.0, 50.0), dx: float | None = None,
        outside: str = "periodic",
    ) -> RailProfile:
        """Random profile of both rails from a spectrum (spectral representation method).

        See the module notes for the spectra, their units and the method.

        Parameters
        ----------
        kind
            ``"fra"`` or ``"iso8608"``.
        track_class
            FRA class 1-6 (6 best), or ISO 8608 class ``"A"``-``"H"`` (A best).
        x_range
            ``(x_start, x_end)`` [m]: the generated length ``L = x_end - x_start``
            is the period of the profile and sets the frequency step ``2 pi / L``.
        seed
            Seed of :func:`numpy.random.default_rng` (the same seed gives the same profile).
        wavelength_range
            ``(lambda_min, lambda_max)`` [m] of the band kept.
        dx
            Grid step [m]; default ``lambda_min / 10`` (rounded down so that the
            grid spans ``x_range`` exactly). Must be below ``lambda_min / 2``.
        outside
            Evaluation outside ``x_range``; default ``"periodic"`` (the profile is
            exactly periodic, so this has no jump).

        Returns
        -------
        RailProfile
            Profile on ``N + 1`` grid points with ``z[:, -1] == z[:, 0]``.
        """
        k, c = _check_kind_class(kind, track_class)
        lmin, lmax = _check_wavelengths(wavelength_range)
        x0, x1 = (float(v) for v in x_range)
        length = x1 - x0
        if not (math.isfinite(length) and length > 0.0):
            raise ValueError(f"x_range must be increasing and finite, got {tuple(x_range)!r}")
        step = lmin / 10.0 if dx is None else float(dx)
        if not step > 0.0:
            raise ValueError(f"dx must be positive, got {dx!r}")
        n = max(2, math.ceil(length / step - 1e-9))
        d_om = 2.0 * np.pi / length
        om_lo, om_hi = 2.0 * np.pi / lmax, 2.0 * np.pi / lmin
        k_lo = max(1, math.floor(om_lo / d_om + 0.5))
        k_hi = math.floor(om_hi / d_om + 0.5)
        if k_hi < 1:
            raise ValueError(f"x_range length {length:g} m is shorter than half the shortest "
                             f"wavelength {lmin:g} m")
        if 2 * k_hi >= n:
            raise ValueError(f"dx = {length / n:g} m is too coarse for lambda_min = {lmin:g} m: "
                             "use dx < lambda_min / 2")
        kk = np.arange(k_lo, k_hi + 1)
        edges = np.clip((np.arange(k_lo, k_hi + 2) - 0.5) * d_om, om_lo, om_hi)
        edges[0] = om_lo
        cum = _cumulative(k, c, edges)
        power = np.maximum(np.diff(cum), 0.0)  # exact band integral of S over each bin
        amp = np.sqrt(2.0 * power)
        phase = np.random.default_rng(seed).uniform(0.0, 2.0 * np.pi, size=(2, kk.size))
        spec = np.zeros((2, n // 2 + 1), dtype=complex)
        spec[:, kk] = 0.5 * n * amp * np.exp(1j * phase)
        z = np.fft.irfft(spec, n=n, axis=1)
        z = np.concatenate([z, z[:, :1]], axis=1)
        x = x0 + length * np.arange(n + 1) / n
        x[-1] = x1
        return cls(x, z, outside=outside)


@dataclass(frozen=True)
class WheelFlat:
    """Haversine wheel flat on one or more wheels.

    While the flat is in contact the wheel sees the rail lowered by
    ``z(s) = -(depth/2) (1 - cos(2 pi s / length))`` for ``0 <= s < length``
    (zero elsewhere), where ``s = (x - phase) mod (2 pi wheel_radius)`` is the
    arc length from the start of the flat to the contact point and ``x`` the
    wheel's position (pure rolling: the wheel has rolled ``x`` since ``x = 0``).
    The flat first hits at ``x = phase`` and repeats every circumference; the
    full depth is reached at ``s = length / 2``. This is the classic "rounded
    flat" input (e.g. Dukkipati & Dong 1999); it is applied as a change of the
    rail height, not as the exact wheel-centre trajectory of a sharp flat (for
    which a chord of length ``l`` has depth ``~ l^2 / (8 R)``).

    Parameters
    ----------
    depth
        Maximum depth [m] (>= 0).
    length
        Length of the flat along the circumference [m], ``0 < length <= 2 pi R``.
    wheels
        Indices of the wheels that have this flat.
    phase
        Arc position of the start of the flat relative to the contact point at
        ``x = 0`` [m]; a scalar or one value per wheel in ``wheels``.
    wheel_radius
        Rolling radius R [m].
    """

    depth: float
    length: float
    wheels: tuple[int, ...]
    phase: float | tuple[float, ...] = 0.0
    wheel_radius: float = 0.46
    _phase: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        wheels = tuple(int(w) for w in np.atleast_1d(self.wheels))
        object.__setattr__(self, "wheels", wheels)
        if not wheels or min(wheels) < 0:
            raise ValueError(f"wheels must be non-empty non-negative indices, got {wheels!r}")
        if not (self.wheel_radius > 0.0):
            raise ValueError(f"wheel_radius must be positive, got {self.wheel_radius!r}")
        if not (self.depth >= 0.0):
            raise ValueError(f"depth must be >= 0, got {self.depth!r}")
        if not (0.0 < self.length <= self.circumference):
            raise ValueError(f"length must be in (0, 2 pi R = {self.circumference:g}], got "
                             f"{self.length!r}")
        ph = np.broadcast_to(np.asarray(self.phase, dtype=float), (len(wheels),)).copy()
        object.__setattr__(self, "_phase", ph)

    @property
    def circumference(self) -> float:
        """Wheel circumference ``2 pi R`` [m]."""
        return 2.0 * np.pi * self.wheel_radius

    def profile(self, x: np.ndarray | float, phase: np.ndarray | float | None = None
                ) -> np.ndarray:
        """Height change seen by a flat wheel at position(s) ``x`` (<= 0).

        Parameters
        ----------
        x
            Wheel position(s) [m].
        phase
            Phase(s) to use; default the first wheel's phase.

        Returns
        -------
        numpy.ndarray
            ``z`` [m], same shape as ``x`` (broadcast with ``phase``).
        """
        ph = self._phase[0] if phase is None else np.asarray(phase, dtype=float)
        s = np.mod(np.asarray(x, dtype=float) - ph, self.circumference)
        z = -0.5 * self.depth * (1.0 - np.cos(2.0 * np.pi * s / self.length))
        return np.where(s < self.length, z, 0.0)

    def add_to(self, heights: np.ndarray, x_wheels: np.ndarray) -> None:
        """Add the flat's effect in place to ``heights`` of the listed wheels.

        Parameters
        ----------
        heights
            (n_wheels,) rail heights under the wheels, modified in place.
        x_wheels
            (n_wheels,) wheel positions [m].
        """
        idx = list(self.wheels)
        heights[idx] += self.profile(x_wheels[idx], self._phase)


class Irregularity:
    """Rail heights under the wheels: rail profile plus wheel flats.

    Callable as ``irregularity(x_wheels)`` (the ``irregularity`` argument of
    the integrators): returns the (n_wheels,) undeformed rail-top heights
    under the wheels [m], including the flats (a flat lowers the height seen by
    its wheel).

    Parameters
    ----------
    profile
        Rail profile, or None for smooth rails.
    flats
        Wheel flats (each lists its wheel indices).
    wheel_rail
        (n_wheels,) rail (0/1) of each wheel, e.g. ``vehicle.wheel_rail``;
        default ``(0, 1)`` for :class:`~.vehicles.SuspendedWheelset`.
    """

    def __init__(self, profile: RailProfile | None = None, flats: Sequence[WheelFlat] = (),
                 wheel_rail: Sequence[int] | np.ndarray = (0, 1)):
        rail = np.array(wheel_rail, dtype=int)
        if rail.ndim != 1 or rail.size == 0 or not np.all((rail == 0) | (rail == 1)):
            raise ValueError(f"wheel_rail must be a non-empty sequence of 0/1, got {wheel_rail!r}")
        self.profile = profile
        self.flats = tuple(flats)
        for fl in self.flats:
            if max(fl.wheels) >= rail.size:
                raise ValueError(f"wheel flat on wheel {max(fl.wheels)} but only {rail.size} "
                                 "wheels (wheel_rail)")
        rail.flags.writeable = False
        self.wheel_rail = rail
        self._n = rail.size

    @property
    def n_wheels(self) -> int:
        """Number of wheels."""
        return self._n

    def __call__(self, x_wheels: np.ndarray) -> np.ndarray:
        """(n_wheels,) rail heights under the wheels at positions ``x_wheels`` [m]."""
        x = np.asarray(x_wheels, dtype=float)
        if x.shape != (self._n,):
            raise ValueError(f"expected ({self._n},) wheel positions, got shape {x.shape}")
        h = (np.zeros(self._n) if self.profile is None
             else self.profile.heights(x, self.wheel_rail))
        for fl in self.flats:
            fl.add_to(h, x)
        return h


__all__ = [
    "FRA_AV",
    "FRA_K",
    "FRA_OMEGA_C",
    "ISO8608_N0",
    "ISO8608_SD0",
    "ISO8608_W",
    "Irregularity",
    "ProfileFileError",
    "RailProfile",
    "WheelFlat",
    "band_variance",
    "psd",
]
