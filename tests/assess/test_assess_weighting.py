"""Weightings and one-third-octave bands against their analytic definitions."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.assess.weighting import (
    KB_F0,
    WM_F1,
    WM_F2,
    WM_F3,
    band_limit_response,
    kb_response,
    third_octave_bands,
    third_octave_rms,
    weight_kb,
    weight_wm,
    wm_response,
)

# Closed forms of the magnitudes (derived by hand from the transfer functions, not from the
# code under test): Butterworth |H|² = 1/(1+(f/fc)^±4); with f3 = f4 and Q4 = 0.5 the a–v
# transition (s+ω3)ω4²/(ω3 (s+ω4)²) reduces to ω4/(s+ω4), |H|² = 1/(1+(f/f3)²).


# the standards' parameters, written out here so that the tests do not share the module's
# constants: Wm f1 = 10^-0.1, f2 = 100, f3 = f4 = 1/(0.028·2π) Hz; KB f0 = 5.6 Hz, band 1–80 Hz
F1, F2, F3, F0 = 10**-0.1, 100.0, 1 / (0.028 * 2 * np.pi), 5.6


def wm_closed(f):
    f = np.asarray(f, float)
    return (1 / np.sqrt(1 + (F1 / f) ** 4) / np.sqrt(1 + (f / F2) ** 4)
            / np.sqrt(1 + (f / F3) ** 2))


def kb_closed(f, band=True):
    f = np.asarray(f, float)
    h = 1 / np.sqrt(1 + (F0 / f) ** 2)
    if band:
        h = h / np.sqrt(1 + (1.0 / f) ** 4) / np.sqrt(1 + (f / 80.0) ** 4)
    return h


# only floating-point round-off separates two evaluations of the same rational function
RTOL_EXACT = 1e-12


def test_wm_parameters():
    assert abs(WM_F1 - 0.7943) <= 5e-5
    assert abs(WM_F3 - 5.684) <= 5e-4
    np.testing.assert_allclose([WM_F1, WM_F2, WM_F3, KB_F0], [F1, F2, F3, F0], rtol=1e-15)


@pytest.mark.parametrize("f", [0.5, 1.0, F3, 5.684, 16.0, 80.0, 100.0, 250.0])
def test_wm_magnitude_matches_definition(f):
    assert abs(wm_response(f)) == pytest.approx(wm_closed(f), rel=RTOL_EXACT)


def test_wm_reference_values():
    # the closed form evaluated by hand to 4 significant digits (tolerance: half a unit of the
    # last digit)
    expected = {1.0: 0.8329, 16.0: 0.3346, 80.0: 0.05970}
    for f, h in expected.items():
        assert abs(wm_response(f)) == pytest.approx(h, abs=5e-5)
    # at the a–v transition the weighting is 1/√2 times the (nearly 1) band limits
    band = abs(band_limit_response(F3, F1, F2))
    assert abs(wm_response(F3)) / band == pytest.approx(1 / np.sqrt(2), rel=RTOL_EXACT)
    # Butterworth stages are -3 dB at their corners
    assert abs(band_limit_response(F1, F1, None)) == pytest.approx(2**-0.5, rel=1e-14)
    assert abs(band_limit_response(F2, None, F2)) == pytest.approx(2**-0.5, rel=1e-14)
    assert wm_response(0.0) == 0


@pytest.mark.parametrize("f", [1.0, 2.0, 5.6, 16.0, 80.0])
def test_kb_magnitude_matches_definition(f):
    assert abs(kb_response(f, band_limit=False)) == pytest.approx(kb_closed(f, False),
                                                                   rel=RTOL_EXACT)
    assert abs(kb_response(f)) == pytest.approx(kb_closed(f, True), rel=RTOL_EXACT)


def test_kb_at_corner_is_half_power():
    assert abs(kb_response(5.6, band_limit=False)) == pytest.approx(1 / np.sqrt(2), rel=1e-14)


def _fit(t, y, f):
    m = np.c_[np.sin(2 * np.pi * f * t), np.cos(2 * np.pi * f * t)]
    c = np.linalg.lstsq(m, y, rcond=None)[0]
    return np.hypot(*c), np.arctan2(c[1], c[0])


# Steady state: the switch-on transient decays as exp(-t/τ), τ <= 0.29 s (the 0.79 Hz
# Butterworth high-pass; 0.23 s for KB's 1 Hz band limit), so after T/3 = 8 s it is below
# e^-27 ≈ 2e-12. The frequency-domain filter treats the record as band-limited: a jump at
# the record's start or end leaves a tail oscillating near fs/2 with amplitude
# <= |H(fs/2)|/(π m) after m samples; worst case KB at fs = 170 Hz (|H(85 Hz)| = 0.66) and
# m >= 8 s·170 Hz: 1.6e-4 pointwise. The least-squares fit over the N >= 1360 samples of the
# middle third projects that tail onto the sinusoid at f, which scales it by at most
# 1/(N |sin((π - ω_f Δt)/2)|) <= 1/(1360·0.092) = 8e-3 (f = 80 Hz), i.e. <= 1.3e-6 in all.
# 1e-5 therefore bounds the error with margin, while a wrong corner frequency or Q is
# caught, and so is a bilinear transform without pre-warping (at fs = 200 Hz it gives the
# 80 Hz sine the analog response of 196 Hz).
RTOL_SINE = 1e-5


@pytest.mark.parametrize("fs", [512.0, 200.0, 170.0])
@pytest.mark.parametrize("f", [1.0, 5.684, 16.0, 80.0])
def test_filtered_sine_has_amplitude_and_phase_of_h(fs, f):
    amp = 0.37
    duration = 24.0
    t = np.arange(int(duration * fs)) / fs
    mid = (t >= duration / 3) & (t < 2 * duration / 3)
    x = amp * np.sin(2 * np.pi * f * t)
    for y, h in ((weight_wm(x, fs), wm_response(f)), (weight_kb(x, fs), kb_response(f))):
        a_fit, phase = _fit(t[mid], y[mid], f)
        assert a_fit == pytest.approx(abs(h) * amp, rel=RTOL_SINE)
        assert np.angle(np.exp(1j * (phase - np.angle(h)))) == pytest.approx(0.0, abs=RTOL_SINE)


@pytest.mark.parametrize("weight", [weight_wm, weight_kb])
def test_weighting_is_causal(weight):
    # a burst at the end of the record must not leak into its start (the zero padding keeps
    # the circular wrap-around of the impulse response out). What remains is the
    # band-limited pre-ringing, <= |H(fs/2)|/(π m) <= 0.1/(π·13·512) ≈ 4.8e-6 of the
    # amplitude at m >= 13 s·512 Hz samples from the burst (|H(256 Hz)| = 0.097 for KB,
    # 0.0033 for Wm)
    fs = 512.0
    t = np.arange(int(20 * fs)) / fs
    x = np.where(t >= 18.0, np.sin(2 * np.pi * 3.0 * t), 0.0)
    y = weight(x, fs)
    assert np.max(np.abs(y[t < 5.0])) <= 4.8e-6
    # and the burst itself is there
    assert np.max(np.abs(y[t >= 18.0])) > 0.3


def test_weighting_multichannel_axis():
    fs = 256.0
    t = np.arange(2048) / fs
    x = np.c_[np.sin(2 * np.pi * 3 * t), np.sin(2 * np.pi * 30 * t)]
    y = weight_wm(x, fs)
    assert y.shape == x.shape
    np.testing.assert_allclose(y[:, 1], weight_wm(x[:, 1], fs), rtol=0, atol=1e-14)
    np.testing.assert_allclose(weight_wm(x.T, fs, axis=1), y.T, rtol=0, atol=1e-14)


def test_third_octave_centres():
    b = third_octave_bands(1.0, 80.0)
    nominal = [1, 1.25, 1.6, 2, 2.5, 3.15, 4, 5, 6.3, 8, 10, 12.5, 16, 20, 25, 31.5, 40, 50,
               63, 80]
    np.testing.assert_allclose(b.nominal, nominal, rtol=1e-12)
    np.testing.assert_allclose(b.centre, 1000 * 10 ** (b.index / 10), rtol=1e-14)
    assert b.index[0] == -30 and b.index[-1] == -11
    # nominal values are within 2 % of the exact base-10 centres (IEC 61260-1 preferred numbers)
    assert np.max(np.abs(b.nominal / b.centre - 1)) < 0.02
    # contiguous edges, one third of a decade-tenth wide: upper/lower = 10^0.1
    np.testing.assert_allclose(b.upper[:-1], b.lower[1:], rtol=1e-14)
    np.testing.assert_allclose(b.upper / b.lower, 10**0.1, rtol=1e-14)
    assert third_octave_bands(1000.0, 1000.0).centre[0] == pytest.approx(1000.0)


def test_sine_energy_in_its_band():
    fs, amp = 512.0, 3.0
    n = 512 * 20  # 20 s: a 16 Hz sine has whole periods, all energy in one bin
    t = np.arange(n) / fs
    spec = third_octave_rms(amp * np.sin(2 * np.pi * 16.0 * t), fs)
    k = int(np.flatnonzero(spec.bands.nominal == 16.0)[0])
    assert spec.rms[k] == pytest.approx(amp / np.sqrt(2), rel=1e-12)
    others = np.delete(spec.rms, k)
    assert np.all(others < 1e-10 * amp)


def test_off_bin_sine_mostly_in_its_band():
    # 12.7 Hz, not on the FFT grid: leakage (Dirichlet kernel) puts the fraction
    # sum_{|j| >= m} 1/(π(j-δ))² <= 2/(π²(m-1)) outside a band whose nearest edge is m bins away
    fs, duration, f = 512.0, 20.0, 12.7
    t = np.arange(int(fs * duration)) / fs
    spec = third_octave_rms(np.sin(2 * np.pi * f * t), fs)
    k = int(np.flatnonzero(spec.bands.nominal == 12.5)[0])
    ms = spec.rms**2
    m = np.floor(min(f - spec.bands.lower[k], spec.bands.upper[k] - f) * duration)
    assert 1 - ms[k] / ms.sum() <= 2 / (np.pi**2 * (m - 1))
    assert ms.sum() == pytest.approx(0.5, rel=2 / (np.pi**2 * (m - 1)))


def test_band_rms_parseval():
    rng = np.random.default_rng(7)
    fs, n = 200.0, 4001  # odd length: no Nyquist bin
    x = rng.standard_normal((n, 2))
    x -= x.mean(axis=0)
    # bands from below the first bin (fs/n = 0.05 Hz) to above Nyquist (100 Hz)
    spec = third_octave_rms(x, fs, fmin=0.04, fmax=125.0)
    assert spec.bands.lower[0] < fs / n and spec.bands.upper[-1] > fs / 2
    np.testing.assert_allclose(np.sum(spec.rms**2, axis=0), np.mean(x**2, axis=0), rtol=1e-12)
    assert spec.n_bins.sum() == n // 2
    # even length: the Nyquist bin counted once
    x2 = x[:-1] - x[:-1].mean(axis=0)
    spec2 = third_octave_rms(x2, fs, fmin=0.04, fmax=125.0)
    np.testing.assert_allclose(np.sum(spec2.rms**2, axis=0), np.mean(x2**2, axis=0),
                               rtol=1e-12)
    # adjacent band ranges add up (bins are partitioned, none counted twice)
    lo = third_octave_rms(x, fs, fmin=1.0, fmax=8.0)
    hi = third_octave_rms(x, fs, fmin=10.0, fmax=80.0)
    full = third_octave_rms(x, fs, fmin=1.0, fmax=80.0)
    np.testing.assert_allclose(np.sum(lo.rms**2, 0) + np.sum(hi.rms**2, 0),
                               np.sum(full.rms**2, 0), rtol=1e-12)


def test_bad_inputs():
    with pytest.raises(ValueError, match="fs"):
        weight_wm(np.ones(10), 0.0)
    with pytest.raises(ValueError, match="fmin"):
        third_octave_bands(10.0, 1.0)
