"""Rail profiles (file, PSD), wheel flats and the per-wheel irregularity callable.

Reference values are computed here independently of the module: the band
integrals of the FRA and ISO 8608 spectra are the closed forms

* FRA: ``1e-4 k A_v [ (1/a - 1/b) - (atan(b/W_c) - atan(a/W_c)) / W_c ]``,
  ``a = 2 pi / lambda_max``, ``b = 2 pi / lambda_min`` [rad/m], ``A_v`` in cm^2 rad/m;
* ISO 8608 (w = 2): ``S_d(n0) n0^2 (1/n_1 - 1/n_2) = S_d(n0) n0^2 (lambda_max - lambda_min)``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from railvib_hpc.errors import UserError
from railvib_hpc.mbs.irregularity import (
    Irregularity,
    ProfileFileError,
    RailProfile,
    WheelFlat,
    band_variance,
    psd,
)

FRA = {1: 1.2107, 2: 1.0181, 3: 0.6816, 4: 0.5376, 5: 0.2095, 6: 0.0339}
ISO = {"A": 16e-6, "B": 64e-6, "C": 256e-6, "D": 1024e-6, "E": 4096e-6, "F": 16384e-6,
       "G": 65536e-6, "H": 262144e-6}
WC = 0.8245


def fra_variance(cls: int, lmin: float, lmax: float) -> float:
    a, b = 2 * math.pi / lmax, 2 * math.pi / lmin
    return 1e-4 * 0.25 * FRA[cls] * ((1 / a - 1 / b) - (math.atan(b / WC) - math.atan(a / WC)) / WC)


def iso_variance(cls: str, lmin: float, lmax: float) -> float:
    return ISO[cls] * 0.1**2 * (lmax - lmin)


# --- files -------------------------------------------------------------------------------


def test_file_round_trip(tmp_path):
    prof = RailProfile.from_psd("fra", 5, (10.0, 210.0), seed=3)
    path = tmp_path / "profile.csv"
    prof.save(path)
    back = RailProfile.from_file(path)
    np.testing.assert_array_equal(back.x, prof.x)
    np.testing.assert_array_equal(back.z, prof.z)


def test_two_column_file_with_header_comments_and_scale(tmp_path):
    path = tmp_path / "p.txt"
    path.write_text("# measured profile, heights in mm\nx z\n\n0.0  1.5\n"
                    "0.5\t-2.0   # a dip\n1.0 0.25\n")
    prof = RailProfile.from_file(path, z_scale=1e-3)
    np.testing.assert_array_equal(prof.x, [0.0, 0.5, 1.0])
    np.testing.assert_allclose(prof.z, [[1.5e-3, -2e-3, 0.25e-3]] * 2, rtol=1e-15)
    # linear interpolation inside, zero outside by default
    assert prof.height(0.25, 0) == pytest.approx(-0.25e-3, rel=1e-12)
    assert prof.height(1.0001, 1) == 0.0 and prof.height(-1.0, 0) == 0.0
    hold = RailProfile.from_file(path, z_scale=1e-3, outside="hold")
    assert hold.height(5.0, 1) == pytest.approx(0.25e-3)


@pytest.mark.parametrize(("text", "message"), [
    ("0 0\n1 abc\n", "line 2, column 2 (z): cannot read 'abc' as a number"),
    ("0, 0, 0\n1, 2, x1\n", "line 2, column 3 (z_rail1): cannot read 'x1'"),
    ("0 0\n1 1 2\n", "line 2: found 3 columns but line 1 has 2"),
    ("# c\n0 0\n1 1\n1 2\n", "line 4, column 1 (x): x = 1 is not greater than x = 1.0 on line 3"),
    ("0 0\n2 0\n1 0\n", "line 3, column 1 (x): x = 1 is not greater"),
    ("0 0 0 0\n", "line 1: expected 2 columns (x, z) or 3 columns"),
    ("0, 0\n1, \n", "line 2, column 2 (z): empty field"),
    ("0 0\n1 nan\n", "line 2, column 2 (z): value 'nan' is not finite"),
    ("# header only\n0 0\n", "needs at least 2 data lines, found 1"),
    ("x z\ny w\n", "line 2, column 1 (x): cannot read 'y'"),
])
def test_file_errors_name_file_line_and_column(tmp_path, text, message):
    path = tmp_path / "bad_profile.txt"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"bad_profile\.txt") as err:
        RailProfile.from_file(path)
    assert message in str(err.value)
    assert isinstance(err.value, ProfileFileError) and isinstance(err.value, UserError)


def test_missing_file(tmp_path):
    with pytest.raises(ProfileFileError, match=r"nope\.txt"):
        RailProfile.from_file(tmp_path / "nope.txt")


def test_profile_constructor_validation():
    with pytest.raises(ValueError, match="strictly increasing"):
        RailProfile([0.0, 1.0, 1.0], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="shape"):
        RailProfile([0.0, 1.0], np.zeros((3, 2)))
    with pytest.raises(ValueError, match="allowed: zero, hold, periodic"):
        RailProfile([0.0, 1.0], [0.0, 0.0], outside="mirror")


# --- spectra -----------------------------------------------------------------------------


def test_kind_and_class_validation():
    with pytest.raises(ValueError, match="allowed: fra, iso8608"):
        RailProfile.from_psd("sncf", 1, (0.0, 100.0), seed=0)
    with pytest.raises(ValueError, match="allowed: 1, 2, 3, 4, 5, 6"):
        RailProfile.from_psd("fra", 7, (0.0, 100.0), seed=0)
    with pytest.raises(ValueError, match="allowed: A, B, C, D, E, F, G, H"):
        band_variance("iso8608", "Z", (1.0, 10.0))
    with pytest.raises(ValueError, match="lambda_min / 2"):
        RailProfile.from_psd("fra", 5, (0.0, 100.0), seed=0, dx=0.6)
    with pytest.raises(ValueError, match="wavelength_range"):
        band_variance("fra", 5, (10.0, 1.0))


@pytest.mark.parametrize("cls", [1, 2, 3, 4, 5, 6])
def test_fra_band_integral(cls):
    assert band_variance("fra", cls, (1.0, 50.0)) == pytest.approx(fra_variance(cls, 1.0, 50.0),
                                                                  rel=1e-13)
    # the closed form against a fine trapezoidal integration of psd()
    om = np.geomspace(2 * np.pi / 50.0, 2 * np.pi, 200_001)
    s = psd("fra", cls, om)
    assert np.sum(0.5 * (s[1:] + s[:-1]) * np.diff(om)) == pytest.approx(
        fra_variance(cls, 1.0, 50.0), rel=1e-8)


@pytest.mark.parametrize(("kind", "cls", "reference"), [
    ("fra", 1, fra_variance), ("fra", 5, fra_variance), ("fra", 6, fra_variance),
    ("iso8608", "A", iso_variance), ("iso8608", "c", iso_variance),
])
def test_psd_profile_variance_equals_band_integral(kind, cls, reference):
    """Harmonics sampled over whole periods: the sample variance is the band integral exactly.

    Measured relative errors are ~1e-15 (float round-off only).
    """
    lmin, lmax = 1.0, 50.0
    prof = RailProfile.from_psd(kind, cls, (0.0, 1000.0), seed=7, wavelength_range=(lmin, lmax))
    z = prof.z[:, :-1]  # one period (the last point repeats the first)
    np.testing.assert_array_equal(prof.z[:, -1], prof.z[:, 0])
    expected = reference(cls.upper() if isinstance(cls, str) else cls, lmin, lmax)
    np.testing.assert_allclose(np.mean(z, axis=1), 0.0, atol=1e-12 * math.sqrt(expected))
    np.testing.assert_allclose(np.mean(z**2, axis=1), expected, rtol=1e-12)


def test_lumped_long_wavelengths_keep_the_variance():
    """A record shorter than lambda_max: the power below the fundamental goes into it."""
    prof = RailProfile.from_psd("fra", 4, (0.0, 30.0), seed=1, wavelength_range=(2.0, 80.0),
                                dx=0.25)
    np.testing.assert_allclose(np.mean(prof.z[:, :-1] ** 2, axis=1),
                               fra_variance(4, 2.0, 80.0), rtol=1e-12)


def _periodogram(prof: RailProfile) -> tuple[np.ndarray, np.ndarray]:
    """One-sided PSD estimate per harmonic: (Omega_k, S_k) with S_k = a_k^2 / (2 dOmega)."""
    z = prof.z[0, :-1]
    n, length = z.size, prof.x[-1] - prof.x[0]
    amp = 2.0 * np.abs(np.fft.rfft(z)) / n
    d_om = 2.0 * np.pi / length
    return np.arange(amp.size) * d_om, amp**2 / (2.0 * d_om)


def test_iso_periodogram_slope_is_minus_two():
    prof = RailProfile.from_psd("iso8608", "B", (0.0, 2000.0), seed=11,
                                wavelength_range=(1.0, 100.0))
    om, s = _periodogram(prof)
    band = (om > 2 * np.pi / 100.0 * 1.5) & (om < 2 * np.pi * 0.99)
    slope, _ = np.polyfit(np.log(om[band] / (2 * np.pi)), np.log(s[band]), 1)
    assert slope == pytest.approx(-2.0, abs=2e-3)  # measured -2.0000 (bin integration)
    assert not np.any(s[om > 2 * np.pi * 1.01] > 1e-12 * s.max())  # nothing outside the band


@pytest.mark.parametrize(("kind", "cls"), [("fra", 3), ("iso8608", "D")])
def test_periodogram_matches_spectrum(kind, cls):
    """Bin powers are exact bin integrals: vs S(Omega_k) dOmega within (dOmega/Omega)^2."""
    prof = RailProfile.from_psd(kind, cls, (0.0, 1000.0), seed=5, wavelength_range=(1.0, 50.0))
    om, s = _periodogram(prof)
    k = np.arange(om.size)
    inner = (k >= 21) & (k <= 999)  # exclude the two bins clipped at the band edges
    np.testing.assert_allclose(s[inner], psd(kind, cls, om[inner]),
                               rtol=1.0 / 21**2)  # midpoint error ~ (5/6) / k^2


def test_seeded_reproducibility_and_independent_rails():
    a = RailProfile.from_psd("fra", 5, (0.0, 500.0), seed=42)
    b = RailProfile.from_psd("fra", 5, (0.0, 500.0), seed=42)
    c = RailProfile.from_psd("fra", 5, (0.0, 500.0), seed=43)
    np.testing.assert_array_equal(a.z, b.z)
    assert np.abs(a.z - c.z).max() > 1e-3
    assert np.abs(a.z[0] - a.z[1]).max() > 1e-3  # two rails, independent phases
    assert a.x[0] == 0.0 and a.x[-1] == 500.0 and np.allclose(np.diff(a.x), 0.1)


def test_periodic_evaluation():
    prof = RailProfile.from_psd("iso8608", "A", (-20.0, 80.0), seed=2)
    x = np.linspace(-20.0, 80.0, 777)
    for rail in (0, 1):
        np.testing.assert_allclose(prof.height(x + 100.0, rail), prof.height(x, rail),
                                   atol=1e-15)
        np.testing.assert_allclose(prof.height(x - 300.0, rail), prof.height(x, rail),
                                   atol=1e-15)


# --- wheel flats ---------------------------------------------------------------------------


def test_flat_depth_length_and_periodicity():
    r, depth, length, phase = 0.46, 0.8e-3, 0.06, 0.3
    flat = WheelFlat(depth, length, wheels=[0], phase=phase, wheel_radius=r)
    circ = 2 * np.pi * r
    assert flat.circumference == circ
    # full depth in the middle, every revolution
    for m in range(4):
        assert flat.profile(phase + m * circ + 0.5 * length) == pytest.approx(-depth, rel=1e-12)
    # support exactly [phase, phase + length) on each revolution
    eps = 1e-9
    s = np.linspace(eps, length - eps, 1001)
    assert np.all(flat.profile(phase + s) < 0.0)
    s_out = np.linspace(length + eps, circ - eps, 1001)
    assert np.all(flat.profile(phase + s_out) == 0.0)
    assert flat.profile(phase) == 0.0
    # haversine shape and periodicity 2 pi R
    x = phase + np.linspace(0.0, length, 101)
    np.testing.assert_allclose(flat.profile(x),
                               -0.5 * depth * (1 - np.cos(2 * np.pi * (x - phase) / length)),
                               atol=1e-15)
    xs = np.linspace(-3.0, 3.0, 5001)
    for m in (1, 2, 7):
        np.testing.assert_allclose(flat.profile(xs + m * circ), flat.profile(xs), atol=1e-12)


def test_flat_validation():
    with pytest.raises(ValueError, match="length"):
        WheelFlat(1e-3, 3.0, wheels=[0], wheel_radius=0.46)
    with pytest.raises(ValueError, match="depth"):
        WheelFlat(-1e-3, 0.05, wheels=[0])
    with pytest.raises(ValueError, match="wheels"):
        WheelFlat(1e-3, 0.05, wheels=[])


# --- per-wheel callable --------------------------------------------------------------------


def test_irregularity_maps_wheels_to_rails_and_adds_flats():
    prof = RailProfile([0.0, 10.0], [[1e-3, 1e-3], [2e-3, 4e-3]])  # rail 1 has a ramp
    flat = WheelFlat(0.5e-3, 0.05, wheels=[2], phase=0.1)
    irr = Irregularity(prof, [flat], wheel_rail=[0, 1, 0, 1])
    x = np.array([5.0, 5.0, 0.1 + 0.025, 5.0])
    h = irr(x)
    np.testing.assert_allclose(h, [1e-3, 3e-3, 1e-3 - 0.5e-3, 3e-3], rtol=1e-12)
    # no profile: flats only, other wheels untouched
    only = Irregularity(flats=[flat], wheel_rail=[0, 1, 0, 1])
    np.testing.assert_allclose(only(x), [0.0, 0.0, -0.5e-3, 0.0], atol=1e-18)
    np.testing.assert_array_equal(Irregularity()(np.array([1.0, 2.0])), [0.0, 0.0])
    with pytest.raises(ValueError, match=r"\(4,\) wheel positions"):
        irr(np.zeros(3))
    with pytest.raises(ValueError, match="only 2 wheels"):
        Irregularity(flats=[flat])


def test_irregularity_flat_phase_per_wheel():
    flat = WheelFlat(1e-3, 0.05, wheels=[0, 1], phase=[0.0, 1.0])
    irr = Irregularity(flats=[flat])
    h = irr(np.array([0.025, 0.025]))
    assert h[0] == pytest.approx(-1e-3) and h[1] == 0.0
    h = irr(np.array([1.025, 1.025]))
    assert h[0] == 0.0 and h[1] == pytest.approx(-1e-3)


def test_fra_spectrum_form_value_and_fitted_range():
    """The FRA form k A_v Omega_c^2 / (Omega^2 (Omega^2 + Omega_c^2)), one-sided, in m^2/(rad/m):
    hand-computed value at Omega = 1 rad/m for class 5, and the default wavelength range."""
    from railvib_hpc.config import load_case

    # 0.25 * 0.2095e-4 m^2 rad/m * 0.6798 / 1.6798 = 5.2375e-6 * 0.40469 = 2.1196e-6
    assert psd("fra", 5, 1.0) == pytest.approx(2.11957e-6, rel=1e-5)
    case = load_case(None, ["irregularity.type=fra"])
    assert case["irregularity.wavelength_min"] == 1.524  # 5 ft, the spectra's fitted range
    assert not case.notes
    note = load_case(None, ["irregularity.type=fra", "irregularity.wavelength_min=1.0"]).notes
    assert len(note) == 1 and "1.524" in note[0] and "irregularity.wavelength_min" in note[0]
    # the default band's variance (class 6, 1.524-30 m) against the closed form above
    assert band_variance("fra", 6, (1.524, 30.0)) == pytest.approx(
        fra_variance(6, 1.524, 30.0), rel=1e-13)
