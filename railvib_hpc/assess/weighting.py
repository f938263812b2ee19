"""Frequency weightings and one-third-octave bands, implemented from their definitions.

Weightings
----------
Every weighting is defined by its analog transfer function :math:`H(s)`, evaluated
exactly at :math:`s = j2\\pi f` (``*_response`` functions). A sampled signal is filtered
**in the frequency domain** (:func:`apply_response`): the signal is zero-padded, its real
FFT is multiplied by the exact :math:`H(j2\\pi f_k)` at the FFT bin frequencies and
transformed back. Compared with a bilinear-transform IIR filter this

* has the exact analog magnitude *and* phase at every frequency below Nyquist, for any
  sample rate (no frequency warping, no pre-warping compromise between the corner
  frequencies of a multi-stage weighting);
* is causal to the extent the analog filter is: the padding (at least the record length
  and at least 20 time constants of the slowest pole) keeps the wrap-around of the
  circular convolution out of the returned samples, so the output starts with the same
  switch-on transient as the analog filter would produce;
* interprets the samples as a band-limited signal: content above Nyquist is unknown and
  is not weighted. The Nyquist bin of an even-length FFT keeps only the real part of
  :math:`H` (what ``irfft`` does). As with any band-limited filter, a record that starts or
  ends while still vibrating leaves a tail of at most :math:`|H(f_s/2)|/(\\pi m)` of the
  jump m samples away from the cut (non-causal only in this band-limited sense); records
  of pass-bys should start and end in quiet.

The cost is one FFT pair of length ~2 ``nt`` per call, negligible next to the solver.

ISO 2631-2:2003 / ISO 8041 :math:`W_m` (acceleration, any direction)::

    H = H_h · H_l · H_t,    ω_i = 2π f_i
    H_h = s² / (s² + ω1 s/Q1 + ω1²)          high-pass band limit, f1 = 10^-0.1 Hz, Q1 = 1/√2
    H_l = ω2² / (s² + ω2 s/Q2 + ω2²)         low-pass band limit,  f2 = 100 Hz,     Q2 = 1/√2
    H_t = (s + ω3)/(s² + ω4 s/Q4 + ω4²)·ω4²/ω3  a–v transition, f3 = f4 = 1/(0.028·2π) Hz, Q4 = 0.5

With f3 = f4 and Q4 = 0.5 the a–v transition reduces to the first-order low-pass
ω4/(s + ω4), so :math:`|W_m| = [1+(f_1/f)^4]^{-1/2}[1+(f/f_2)^4]^{-1/2}[1+(f/f_3)^2]^{-1/2}`.
The upward step is absent (f5 = f6 = ∞) and K = 1.

DIN 4150-2 KB weighting (velocity): :math:`H_{KB}(s) = s/(s + 2\\pi f_0)`, f0 = 5.6 Hz, so
:math:`|H_{KB}| = 1/\\sqrt{1+(f_0/f)^2}`. DIN 4150-2 evaluates KB in the band 1–80 Hz
(measurement chain of DIN 45669-1). **Choice:** by default the band is applied as
second-order Butterworth high-pass (1 Hz) and low-pass (80 Hz) stages of the same form as
the ISO 8041 band limiting above (``band_limit=True``); ``band_limit=False`` gives the bare
KB high-pass. The Butterworth band edges are smooth (-3 dB at 1 and 80 Hz), unlike a
brick-wall cut, so the weighted signal stays causal and free of ringing.

One-third-octave bands
----------------------
Base-10 bands (IEC 61260-1): exact centres ``fc = 1000·10^(k/10)`` Hz, edges
``fc·10^(±1/20)``, so neighbouring bands share their edges exactly. Nominal centres are the
preferred numbers 1, 1.25, 1.6, 2, 2.5, 3.15, 4, 5, 6.3, 8 times a power of ten. Band RMS
values are sums of the one-sided power spectrum over the FFT bins inside each band
(:func:`third_octave_rms`); the bins are partitioned, hence the sum of the band mean
squares equals the mean square of the spectrum part the bands cover (Parseval).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.fft import irfft, next_fast_len, rfft, rfftfreq

from ..constants import THIRD_OCTAVE_MANTISSAS

__all__ = [
    "KB_F0",
    "KB_F_HIGH",
    "KB_F_LOW",
    "WM_F1",
    "WM_F2",
    "WM_F3",
    "WM_F4",
    "WM_Q4",
    "BandSpectrum",
    "ThirdOctaveBands",
    "apply_response",
    "band_limit_response",
    "kb_response",
    "third_octave_bands",
    "third_octave_rms",
    "weight_kb",
    "weight_wm",
    "wm_response",
]

#: ISO 8041 Wm: band-limiting high-pass corner 10^-0.1 Hz.
WM_F1 = 10.0**-0.1
#: ISO 8041 Wm: band-limiting low-pass corner [Hz].
WM_F2 = 100.0
#: ISO 8041 Wm: a–v transition corners f3 = f4 = 1/(0.028·2π) = 5.684 Hz.
WM_F3 = 1.0 / (0.028 * 2.0 * np.pi)
WM_F4 = WM_F3
#: ISO 8041 Wm: a–v transition quality factor.
WM_Q4 = 0.5
#: Butterworth quality factor of the band-limiting stages.
Q_BUTTERWORTH = 1.0 / np.sqrt(2.0)
#: DIN 4150-2 KB high-pass corner [Hz].
KB_F0 = 5.6
#: DIN 4150-2 KB band [Hz].
KB_F_LOW = 1.0
KB_F_HIGH = 80.0

#: Preferred (nominal) mantissas of the base-10 one-third-octave centres.
_NOMINAL_MANTISSA = np.array(THIRD_OCTAVE_MANTISSAS)

Response = Callable[[np.ndarray], np.ndarray]


def _s(f) -> np.ndarray:
    """Laplace variable s = j 2π f of frequencies ``f`` [Hz]."""
    return 2j * np.pi * np.asarray(f, dtype=float)


def band_limit_response(f, f_low: float | None, f_high: float | None,
                        q: float = Q_BUTTERWORTH) -> np.ndarray:
    """Second-order high-pass × low-pass band limiting, as in ISO 8041.

    Parameters
    ----------
    f
        Frequencies [Hz] (any shape).
    f_low, f_high
        High-pass and low-pass corner frequencies [Hz]; ``None`` omits that stage.
    q
        Quality factor of both stages (1/√2: Butterworth).

    Returns
    -------
    numpy.ndarray
        Complex :math:`H(j2\\pi f)`, shape of ``f``.
    """
    s = _s(f)
    h = np.ones_like(s)
    if f_low is not None:
        w1 = 2.0 * np.pi * f_low
        h = h * s**2 / (s**2 + w1 * s / q + w1**2)
    if f_high is not None:
        w2 = 2.0 * np.pi * f_high
        h = h * w2**2 / (s**2 + w2 * s / q + w2**2)
    return h


def wm_response(f) -> np.ndarray:
    """ISO 2631-2:2003 / ISO 8041 :math:`W_m` weighting of acceleration, :math:`H(j2\\pi f)`.

    Parameters
    ----------
    f
        Frequencies [Hz] (any shape, ``f = 0`` gives 0).

    Returns
    -------
    numpy.ndarray
        Complex response (band limiting × a–v transition, K = 1), shape of ``f``.
    """
    s = _s(f)
    w3 = 2.0 * np.pi * WM_F3
    w4 = 2.0 * np.pi * WM_F4
    h_t = (s + w3) / (s**2 + w4 * s / WM_Q4 + w4**2) * w4**2 / w3
    return band_limit_response(f, WM_F1, WM_F2) * h_t


def kb_response(f, band_limit: bool = True) -> np.ndarray:
    """DIN 4150-2 KB weighting of velocity, :math:`H(j2\\pi f)`.

    Parameters
    ----------
    f
        Frequencies [Hz] (any shape).
    band_limit
        Multiply by the 1–80 Hz second-order Butterworth band limits (see module
        docstring); ``False`` gives the bare KB high-pass ``s/(s + 2π·5.6)``.

    Returns
    -------
    numpy.ndarray
        Complex response, shape of ``f``.
    """
    s = _s(f)
    h = s / (s + 2.0 * np.pi * KB_F0)
    if band_limit:
        h = h * band_limit_response(f, KB_F_LOW, KB_F_HIGH)
    return h


def _check_fs(fs) -> float:
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0.0:
        raise ValueError(f"fs = {fs!r}: the sample rate must be a positive finite number [Hz]")
    return fs


def apply_response(x, fs: float, response: Response, *, axis: int = 0,
                   settle_time: float = 0.0) -> np.ndarray:
    """Filter a sampled signal with an analog transfer function, in the frequency domain.

    Parameters
    ----------
    x
        Signal, uniformly sampled along ``axis``.
    fs
        Sample rate [Hz].
    response
        ``response(f) -> H(j2πf)`` (complex, vectorised over ``f`` in Hz).
    axis
        Time axis of ``x``.
    settle_time
        Decay time [s] of the filter's slowest pole; the zero padding is at least the
        record length and at least ``settle_time`` so that the circular wrap-around of the
        filter's impulse response does not reach the returned samples.

    Returns
    -------
    numpy.ndarray
        Filtered signal, same shape as ``x`` (float64).
    """
    fs = _check_fs(fs)
    x = np.asarray(x, dtype=float)
    n = x.shape[axis]
    if n == 0:
        return x.copy()
    n_pad = max(n, int(np.ceil(settle_time * fs)))
    nfft = next_fast_len(n + n_pad, real=True)
    spec = rfft(x, n=nfft, axis=axis)
    h = np.asarray(response(rfftfreq(nfft, d=1.0 / fs)), dtype=complex)
    shape = [1] * x.ndim
    shape[axis] = h.size
    y = irfft(spec * h.reshape(shape), n=nfft, axis=axis)
    return np.take(y, np.arange(n), axis=axis)


def _wm_settle() -> float:
    # slowest pole: the 0.794 Hz band-limiting high-pass, decay rate ω1/(2Q1); 20 time constants
    return 20.0 * 2.0 * Q_BUTTERWORTH / (2.0 * np.pi * WM_F1)


def weight_wm(a, fs: float, *, axis: int = 0) -> np.ndarray:
    """Apply the :math:`W_m` weighting to an acceleration history.

    Parameters
    ----------
    a
        Acceleration [any unit], uniformly sampled along ``axis``.
    fs
        Sample rate [Hz]. Content above ``fs/2`` (including the upper band limit 100 Hz
        when ``fs < 200`` Hz) cannot be weighted.
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        Weighted acceleration :math:`a_w(t)`, same shape and unit as ``a``.
    """
    return apply_response(a, fs, wm_response, axis=axis, settle_time=_wm_settle())


def weight_kb(v, fs: float, *, axis: int = 0, band_limit: bool = True) -> np.ndarray:
    """Apply the DIN 4150-2 KB weighting to a velocity history.

    Parameters
    ----------
    v
        Velocity [any unit; DIN 4150-2 guide values are in mm/s], sampled along ``axis``.
    fs
        Sample rate [Hz].
    axis
        Time axis.
    band_limit
        Apply the 1–80 Hz Butterworth band limits (default) as well.

    Returns
    -------
    numpy.ndarray
        KB(t), same shape and unit as ``v``.
    """
    if band_limit:
        settle = 20.0 * 2.0 * Q_BUTTERWORTH / (2.0 * np.pi * KB_F_LOW)
    else:
        settle = 20.0 / (2.0 * np.pi * KB_F0)
    return apply_response(v, fs, lambda f: kb_response(f, band_limit=band_limit), axis=axis,
                          settle_time=settle)


# --------------------------------------------------------------------------------------
# one-third-octave bands


@dataclass(frozen=True)
class ThirdOctaveBands:
    """Base-10 one-third-octave bands.

    Attributes
    ----------
    index
        Band numbers k, ``centre = 1000·10^(k/10)`` Hz.
    centre
        Exact mid-band frequencies [Hz].
    nominal
        Nominal (preferred-number) centres [Hz], used for labels and limit curves.
    lower, upper
        Band edges ``centre·10^(∓1/20)`` [Hz].
    """

    index: np.ndarray
    centre: np.ndarray
    nominal: np.ndarray
    lower: np.ndarray
    upper: np.ndarray

    @property
    def edges(self) -> np.ndarray:
        """(n_bands + 1,) contiguous band edges [Hz]."""
        return np.append(self.lower, self.upper[-1])


def third_octave_bands(fmin: float = 1.0, fmax: float = 80.0) -> ThirdOctaveBands:
    """The one-third-octave bands whose nominal centres lie in ``[fmin, fmax]``.

    Parameters
    ----------
    fmin, fmax
        Range of nominal centre frequencies [Hz], ``0 < fmin <= fmax``.

    Returns
    -------
    ThirdOctaveBands
        The bands, in ascending order.
    """
    fmin, fmax = float(fmin), float(fmax)
    if not (np.isfinite(fmin) and np.isfinite(fmax) and 0.0 < fmin <= fmax):
        raise ValueError(f"(fmin, fmax) = ({fmin!r}, {fmax!r}): need 0 < fmin <= fmax [Hz]")
    # nominal centres are within 1.3 % of the exact ones, so rounding the band number is exact
    k0 = int(np.round(10.0 * np.log10(fmin / 1000.0)))
    k1 = int(np.round(10.0 * np.log10(fmax / 1000.0)))
    k = np.arange(k0 - 1, k1 + 2)
    nominal = _NOMINAL_MANTISSA[np.mod(k, 10)] * 10.0 ** (np.floor_divide(k, 10) + 3)
    keep = (nominal >= fmin * (1 - 1e-9)) & (nominal <= fmax * (1 + 1e-9))
    if not keep.any():
        raise ValueError(f"(fmin, fmax) = ({fmin!r}, {fmax!r}): no one-third-octave band has "
                         "its nominal centre in this range")
    k = k[keep]
    centre = 1000.0 * 10.0 ** (k / 10.0)
    return ThirdOctaveBands(index=k, centre=centre, nominal=nominal[keep],
                            lower=1000.0 * 10.0 ** ((k - 0.5) / 10.0),
                            upper=1000.0 * 10.0 ** ((k + 0.5) / 10.0))


@dataclass(frozen=True)
class BandSpectrum:
    """One-third-octave RMS spectrum of a signal.

    Attributes
    ----------
    bands
        The bands.
    rms
        (n_bands, ...) band RMS values (unit of the signal); leading axis = band, the
        other axes are the signal's non-time axes.
    n_bins
        (n_bands,) number of FFT bins inside each band; a band with 0 bins is below the
        frequency resolution ``fs/nt`` of the record (its RMS is reported as 0) and a
        band with few bins is coarse.
    """

    bands: ThirdOctaveBands
    rms: np.ndarray
    n_bins: np.ndarray


def third_octave_rms(x, fs: float, *, fmin: float = 1.0, fmax: float = 80.0,
                     axis: int = 0) -> BandSpectrum:
    """One-third-octave band RMS values of a record, from its power spectrum.

    The one-sided power spectrum ``P_k`` of the whole record (rectangular window, no
    padding) satisfies ``sum_k P_k = mean(x²)``. Each FFT bin with ``lower <= f_k < upper``
    of a band contributes to that band, so ``rms_b = sqrt(sum_{k in b} P_k)`` and the sum
    of the band mean squares equals the mean square of all bins the bands cover.

    Parameters
    ----------
    x
        Signal, uniformly sampled along ``axis``.
    fs
        Sample rate [Hz].
    fmin, fmax
        Range of nominal band centres [Hz].
    axis
        Time axis.

    Returns
    -------
    BandSpectrum
        Band RMS values over the whole record.
    """
    fs = _check_fs(fs)
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    n = x.shape[0]
    if n < 2:
        raise ValueError(f"x has {n} samples along axis {axis}: need at least 2")
    bands = third_octave_bands(fmin, fmax)
    spec = rfft(x, axis=0)
    power = np.abs(spec) ** 2 / float(n) ** 2
    power[1:] *= 2.0
    if n % 2 == 0:
        power[-1] /= 2.0  # the Nyquist bin is not mirrored
    f = rfftfreq(n, d=1.0 / fs)
    band_of_bin = np.searchsorted(bands.edges, f, side="right") - 1
    inside = (band_of_bin >= 0) & (band_of_bin < bands.centre.size)
    ms = np.zeros((bands.centre.size,) + x.shape[1:])
    np.add.at(ms, band_of_bin[inside], power[inside])
    n_bins = np.bincount(band_of_bin[inside], minlength=bands.centre.size)
    return BandSpectrum(bands=bands, rms=np.sqrt(ms), n_bins=n_bins)
