"""Metrics against closed-form values for sines and constants."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.assess.metrics import (
    FTA_V_REF,
    fta_vdb,
    kb_fmax,
    kb_ftm,
    linear_running_rms,
    mtvv,
    peak,
    ppv,
    rms,
    running_rms,
    vdv,
)
from railvib_hpc.assess.weighting import kb_response


def sine(amp, f, fs, duration, endpoint=False):
    n = int(round(duration * fs)) + (1 if endpoint else 0)
    t = np.arange(n) / fs
    return t, amp * np.sin(2 * np.pi * f * t)


def ripple(f, tau):
    """Steady-state running mean square of a sine: A²/2 [1 + ε cos(...)], ε = 1/√(1+(2ωτ)²)."""
    return 1.0 / np.sqrt(1.0 + (2 * 2 * np.pi * f * tau) ** 2)


def ripple_tolerance(f, fs, tau):
    """Relative bound on the discrete max of the running RMS of a sine.

    Only the ripple ε of the mean square is affected by the sampling: the first-order hold of
    u = a² between samples changes the ripple by at most (2ωΔt)²/12, and sampling its maximum
    loses at most 1 - cos(ωΔt) <= (ωΔt)²/2. The RMS (square root) halves the relative error;
    the bound below keeps a factor 2 margin.
    """
    wdt = 2 * np.pi * f / fs
    return ripple(f, tau) * ((2 * wdt) ** 2 / 12 + wdt**2 / 2)


def test_rms_and_peak_of_sine():
    amp = 2.5
    _, x = sine(amp, 10.0, 1000.0, 3.0)  # whole periods, sample on the crest (t = 25 ms)
    assert rms(x) == pytest.approx(amp / np.sqrt(2), rel=1e-13)
    assert peak(x) == pytest.approx(amp, rel=1e-13)
    np.testing.assert_allclose(rms(np.c_[x, 2 * x]), [amp / np.sqrt(2), amp * np.sqrt(2)],
                               rtol=1e-13)


@pytest.mark.parametrize("f, fs, periods", [(10.0, 1000.0, 30), (2.5, 200.0, 5)])
def test_vdv_of_sine_over_whole_periods(f, fs, periods):
    # ∫ sin⁴ over whole periods = 3T/8; the trapezoidal sum of sin⁴ over n > 4 samples per
    # period is exact (cos 2x, cos 4x sum to zero), so only round-off remains
    amp = 1.7
    duration = periods / f
    n = periods * fs / f
    assert n == int(n)
    _, x = sine(amp, f, fs, duration, endpoint=True)
    assert vdv(x, fs) == pytest.approx(amp * (3 * duration / 8) ** 0.25, rel=1e-12)


def test_running_rms_of_constant():
    # y(t) = c² (1 - exp(-t/τ)) exactly (the first-order hold is exact for a constant)
    fs, tau, c = 100.0, 0.5, 3.0
    t = np.arange(700) / fs
    y = running_rms(np.full(t.size, c), fs, tau)
    np.testing.assert_allclose(y, c * np.sqrt(1 - np.exp(-t / tau)), rtol=1e-12, atol=1e-12)
    assert y[0] == 0.0


def test_running_rms_matches_definition_for_piecewise_linear_square():
    # the recursion integrates 1/τ ∫ u(t) exp((t-t0)/τ) dt exactly for u linear between
    # samples; compare with scipy quad of that integral at a few t0
    from scipy.integrate import quad

    rng = np.random.default_rng(3)
    fs, tau = 50.0, 0.2
    x = rng.standard_normal(60)
    t = np.arange(x.size) / fs
    y = running_rms(x, fs, tau) ** 2
    for n in (1, 17, 59):
        def integrand(s, t0=t[n]):
            return np.interp(s, t, x * x) * np.exp((s - t0) / tau) / tau

        val = sum(quad(integrand, t[k], t[k + 1], epsabs=1e-14, epsrel=1e-12)[0]
                  for k in range(n))
        assert y[n] == pytest.approx(val, rel=1e-10)


@pytest.mark.parametrize("f", [2.0, 10.0, 40.0])
def test_mtvv_of_long_sine(f):
    amp, fs, tau = 0.8, 1000.0, 1.0
    _, x = sine(amp, f, fs, 30.0)  # start transient exp(-30) ≈ 1e-13
    expected = amp / np.sqrt(2) * np.sqrt(1 + ripple(f, tau))
    assert mtvv(x, fs, tau) == pytest.approx(expected, rel=ripple_tolerance(f, fs, tau))
    # and it tends to A/√2: the excess is the ripple, which vanishes for fτ -> ∞
    assert 0 < mtvv(x, fs, tau) / (amp / np.sqrt(2)) - 1 <= ripple(f, tau) / 2 * 1.0001


def test_linear_running_rms_of_sine():
    amp, fs = 1.3, 400.0
    _, x = sine(amp, 5.0, fs, 4.0)
    r = linear_running_rms(x, fs, 1.0)  # every 1 s window holds 5 whole periods
    assert r.shape == (x.size - 400 + 1,)
    np.testing.assert_allclose(r, amp / np.sqrt(2), rtol=1e-12)


def test_fta_vdb_of_sine():
    amp, fs, f = 2e-4, 1000.0, 8.0  # 0.2 mm/s
    _, v = sine(amp, f, fs, 20.0)
    # rectangular 1 s window over whole periods: the RMS is exactly A/√2
    lin = fta_vdb(v, fs, averaging="linear")
    assert lin == pytest.approx(20 * np.log10(amp / np.sqrt(2) / 2.54e-8), abs=1e-9)
    assert abs(FTA_V_REF - 2.54e-8) <= 1e-15 * 2.54e-8
    # exponential τ = 1 s: the max includes the ripple, tolerance as for MTVV (in dB)
    expo = fta_vdb(v, fs)
    expected = 20 * np.log10(amp / np.sqrt(2) * np.sqrt(1 + ripple(f, 1.0)) / 2.54e-8)
    assert expo == pytest.approx(expected, abs=20 * np.log10(1 + ripple_tolerance(f, fs, 1.0)))


@pytest.mark.parametrize("method", ["zero_crossing", "spectrum"])
def test_ppv_and_frequency_of_sine(method):
    amp, fs, f, duration = 4.0, 1000.0, 7.3, 10.0
    t, v = sine(amp, f, fs, duration)
    p, freq = ppv(np.c_[v, -0.5 * v], fs, method=method)
    # the sampled crest is within 1 - cos(πf/fs) of the true one
    np.testing.assert_allclose(p, [amp, 0.5 * amp], rtol=1 - np.cos(np.pi * f / fs))
    if method == "zero_crossing":
        # linear interpolation of a crossing errs by < Δt (ωΔt)²/8 each: relative on the half
        # period 2·Δt(ωΔt)²/8 · 2f
        wdt = 2 * np.pi * f / fs
        tol = 2 * (wdt**2 / 8) / fs * 2 * f
    else:
        tol = fs / (8 * t.size) / f  # one bin of the 8× zero-padded spectrum (next_fast_len >= 8n)
    np.testing.assert_allclose(freq, f, rtol=tol)


def test_ppv_frequency_is_that_of_the_peak_cycle():
    # a Hann-windowed 25 Hz burst (crest at t = 5 s, zero crossings exactly on the samples
    # at 5 ± 0.01 s): the zero-crossing method returns 25 Hz up to round-off
    fs = 2000.0
    t = np.arange(int(10 * fs)) / fs
    window = np.where(np.abs(t - 5.0) < 0.08, np.cos(np.pi * (t - 5.0) / 0.16) ** 2, 0.0)
    burst = window * np.cos(2 * np.pi * 25 * (t - 5.0))
    p, fz = ppv(burst[:, None], fs)
    assert p[0] == pytest.approx(1.0, rel=1e-14)
    assert fz[0] == pytest.approx(25.0, rel=1e-9)
    # on a long weaker 4 Hz sine the spectral maximum is at 4 Hz (amplitude density 0.3·10/2
    # against ≈ 0.04 of the burst): the spectrum method reports the record's dominant
    # frequency, not the peak cycle's; tolerance one bin of the 8× padded spectrum
    v2 = burst + 0.3 * np.sin(2 * np.pi * 4 * t)
    _, fspec = ppv(v2[:, None], fs, method="spectrum")
    assert fspec[0] == pytest.approx(4.0, abs=fs / (8 * t.size))


def test_kb_fmax_of_sine_plateau():
    # tapered sine (1 s cos² ramps, 16 s plateau): on the plateau KB_F is the steady running
    # RMS of |H_KB| A sin, max = |H| A/√2 √(1+ε) with τ = 0.125 s. Weighting error <= 1e-5
    # (see test_assess_weighting), plus the ripple sampling bound.
    fs, f, amp, tau = 1000.0, 20.0, 0.9, 0.125
    t = np.arange(int(20 * fs)) / fs
    env = np.clip(np.minimum(t - 1.0, 19.0 - t), 0.0, 1.0)
    env = np.sin(0.5 * np.pi * env) ** 2
    v = amp * env * np.sin(2 * np.pi * f * t)
    expected = abs(kb_response(f)) * amp / np.sqrt(2) * np.sqrt(1 + ripple(f, tau))
    assert kb_fmax(v, fs) == pytest.approx(expected, rel=1e-5 + ripple_tolerance(f, fs, tau))


def test_kb_ftm_cycles():
    fs = 10.0
    kbf = np.zeros(int(75 * fs))  # 75 s: cycles [0,30), [30,60), [60,75) -> 3 cycles
    kbf[5], kbf[400], kbf[700] = 0.3, 0.4, 0.1
    kbf[6] = 0.2
    val, n = kb_ftm(kbf, fs)
    assert n == 3
    assert val == pytest.approx(np.sqrt((0.3**2 + 0.4**2 + 0.1**2) / 3), rel=1e-14)


def test_metric_input_checks():
    with pytest.raises(ValueError, match="tau"):
        running_rms(np.ones(10), 10.0, tau=0.0)
    with pytest.raises(ValueError, match="method"):
        ppv(np.ones(10), 10.0, method="fft")
    with pytest.raises(ValueError, match="averaging"):
        fta_vdb(np.ones(10), 10.0, averaging="peak")
    with pytest.raises(ValueError, match="samples"):
        vdv(np.ones(1), 10.0)
