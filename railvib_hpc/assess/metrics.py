"""Single-number vibration metrics of sampled histories (vectorised, any number of channels).

All functions take a signal uniformly sampled along ``axis`` (default 0, so a ``(nt, 3)``
history gives one value per direction) and its sample rate ``fs`` [Hz]; units are kept
(the caller converts, e.g. m/s to mm/s for DIN 4150).

Running RMS (ISO 2631-1:1997 eq. 8, exponential averaging)::

    a_w(t0) = [ 1/τ ∫_{-∞}^{t0} a_w²(t) exp((t - t0)/τ) dt ]^½

is the output of the first-order low-pass τ y' + y = a_w² (y = 0 before the record) and is
integrated *exactly* for a_w² varying linearly between samples (first-order hold), with
α = exp(-Δt/τ), r = Δt/τ::

    y_n = α y_{n-1} + (1 - (1-α)/r) u_n + ((1-α)/r - α) u_{n-1},   u = a_w²

(a recursive filter evaluated by :func:`scipy.signal.lfilter`, no Python loop over samples).
τ = 1 s ("slow") gives MTVV = max_t a_w(t); τ = 0.125 s ("fast") gives DIN 4150-2 KB_F(t).

Dominant frequency of the peak particle velocity (DIN 4150-3): by default from the **zero
crossings** around the peak: the (linearly interpolated) zero crossings just before and just
after the absolute peak bound a half period, f = 1/(2 (t_after - t_before)). This is the
frequency of the cycle that carries the peak, which is what DIN 4150-3 compares with the
frequency-dependent limit; it is robust for transient, non-stationary records. If the peak
has no zero crossing on one side (e.g. a drifting record), the spectral method is used for
that channel: the frequency of the largest amplitude of the (8× zero-padded) spectrum.
"""

from __future__ import annotations

import numpy as np
from scipy.fft import next_fast_len, rfft, rfftfreq
from scipy.signal import lfilter

from ..constants import METRES_PER_INCH
from .weighting import weight_kb

__all__ = [
    "FTA_V_REF",
    "TAU_FAST",
    "TAU_SLOW",
    "fta_vdb",
    "kb_f",
    "kb_fmax",
    "kb_ftm",
    "linear_running_rms",
    "mtvv",
    "peak",
    "ppv",
    "rms",
    "running_rms",
    "vdv",
    "velocity_level",
]

#: "slow" time constant [s] (ISO 2631-1 MTVV, FTA 1 s RMS).
TAU_SLOW = 1.0
#: "fast" time constant [s] (DIN 4150-2 KB_F).
TAU_FAST = 0.125
#: FTA reference velocity 1e-6 in/s in m/s (FTA-VA-90-1003-06, section 5.1).
FTA_V_REF = 1e-6 * METRES_PER_INCH


def _prep(x, fs, axis: int) -> tuple[np.ndarray, float]:
    fs = float(fs)
    if not np.isfinite(fs) or fs <= 0.0:
        raise ValueError(f"fs = {fs!r}: the sample rate must be a positive finite number [Hz]")
    x = np.moveaxis(np.asarray(x, dtype=float), axis, 0)
    if x.shape[0] < 2:
        raise ValueError(f"the signal has {x.shape[0]} samples along axis {axis}: need >= 2")
    return x, fs


def rms(x, *, axis: int = 0) -> np.ndarray:
    """Root mean square over the record, ``sqrt(mean(x²))``.

    Parameters
    ----------
    x
        Signal.
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        RMS per channel (a 0-d array for a 1-D signal).
    """
    x = np.asarray(x, dtype=float)
    return np.sqrt(np.mean(x * x, axis=axis))


def peak(x, *, axis: int = 0) -> np.ndarray:
    """Largest absolute value, ``max |x|``.

    Parameters
    ----------
    x
        Signal.
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        Peak per channel.
    """
    return np.max(np.abs(np.asarray(x, dtype=float)), axis=axis)


def running_rms(x, fs: float, tau: float = TAU_SLOW, *, axis: int = 0) -> np.ndarray:
    """Exponential running RMS with time constant ``tau`` (ISO 2631-1 eq. 8).

    Parameters
    ----------
    x
        Signal (e.g. weighted acceleration).
    fs
        Sample rate [Hz].
    tau
        Integration time constant [s] (1 s "slow", 0.125 s "fast").
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        Running RMS, same shape as ``x``; the integral starts at the first sample (the
        signal is taken as zero before the record).
    """
    x, fs = _prep(x, fs, axis)
    tau = float(tau)
    if not np.isfinite(tau) or tau <= 0.0:
        raise ValueError(f"tau = {tau!r}: the time constant must be a positive number [s]")
    r = 1.0 / (fs * tau)
    alpha = np.exp(-r)
    c = -np.expm1(-r) / r  # (1 - α)/r, accurate for small r
    b = np.array([1.0 - c, c - alpha])
    u = x * x
    # lfilter starts from u_{-1} = y_{-1} = 0, giving z_0 = b_0 u_0; the integral from the
    # first sample has y_0 = 0. Both obey the same recursion, so y_n = z_n - α^n b_0 u_0.
    z = lfilter(b, [1.0, -alpha], u, axis=0)
    decay = np.exp(-r * np.arange(u.shape[0])).reshape((-1,) + (1,) * (u.ndim - 1))
    y = z - decay * (b[0] * u[0])
    return np.moveaxis(np.sqrt(np.maximum(y, 0.0)), 0, axis)


def linear_running_rms(x, fs: float, window: float = 1.0, *, axis: int = 0) -> np.ndarray:
    """RMS over a sliding rectangular window of ``window`` seconds (linear averaging).

    Parameters
    ----------
    x
        Signal.
    fs
        Sample rate [Hz].
    window
        Window length [s]; rounded to a whole number of samples ``w >= 1``.
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        (nt - w + 1, ...) RMS of each complete window, along ``axis``; a record shorter
        than the window gives one value, the RMS over the whole record.
    """
    x, fs = _prep(x, fs, axis)
    w = max(1, int(round(float(window) * fs)))
    w = min(w, x.shape[0])
    c = np.concatenate([np.zeros((1,) + x.shape[1:]), np.cumsum(x * x, axis=0)], axis=0)
    ms = (c[w:] - c[:-w]) / w
    return np.moveaxis(np.sqrt(np.maximum(ms, 0.0)), 0, axis)


def mtvv(x, fs: float, tau: float = TAU_SLOW, *, axis: int = 0) -> np.ndarray:
    """Maximum transient vibration value: the maximum of the running RMS.

    Parameters
    ----------
    x
        Weighted acceleration.
    fs
        Sample rate [Hz].
    tau
        Time constant [s] (ISO 2631-1: 1 s).
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        MTVV per channel.
    """
    return np.max(running_rms(x, fs, tau, axis=axis), axis=axis)


def vdv(x, fs: float, *, axis: int = 0) -> np.ndarray:
    """Vibration dose value ``(∫ x⁴ dt)^¼`` (trapezoidal rule over the record).

    Parameters
    ----------
    x
        Weighted acceleration [m/s²] → VDV in m/s^1.75.
    fs
        Sample rate [Hz].
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        VDV per channel.
    """
    x, fs = _prep(x, fs, axis)
    x4 = x**4
    integral = (np.sum(x4, axis=0) - 0.5 * (x4[0] + x4[-1])) / fs
    return integral**0.25


def _spectral_peak_frequency(x: np.ndarray, fs: float) -> np.ndarray:
    """Frequency of the largest spectral amplitude (DC excluded) per column of ``x``."""
    n = x.shape[0]
    nfft = next_fast_len(8 * n, real=True)
    amp = np.abs(rfft(x - x.mean(axis=0), n=nfft, axis=0))
    amp[0] = 0.0
    f = rfftfreq(nfft, d=1.0 / fs)
    return f[np.argmax(amp, axis=0)]


def ppv(v, fs: float, *, method: str = "zero_crossing",
        axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Peak particle velocity and its dominant frequency, per channel.

    Parameters
    ----------
    v
        Velocity.
    fs
        Sample rate [Hz].
    method
        ``"zero_crossing"`` (default: half period between the zero crossings around the
        peak, falling back to the spectrum when a crossing is missing) or ``"spectrum"``
        (frequency of the largest spectral amplitude of the whole record).
    axis
        Time axis.

    Returns
    -------
    ppv : numpy.ndarray
        ``max |v|`` per channel.
    frequency : numpy.ndarray
        Dominant frequency [Hz] per channel (NaN for an all-zero channel).
    """
    if method not in ("zero_crossing", "spectrum"):
        raise ValueError(f"method = {method!r}: allowed are 'zero_crossing' and 'spectrum'")
    x, fs = _prep(v, fs, axis)
    shape = x.shape[1:]
    x = x.reshape(x.shape[0], -1)
    n, m = x.shape
    ipk = np.argmax(np.abs(x), axis=0)
    cols = np.arange(m)
    peak_v = np.abs(x[ipk, cols])
    freq = _spectral_peak_frequency(x, fs)
    if method == "zero_crossing":
        a, b = x[:-1], x[1:]
        # crossing in [i, i+1): sign change, or an exact zero at i
        cross = (a * b < 0.0) | ((a == 0.0) & (b != 0.0))
        i = np.arange(n - 1)[:, None]
        before = np.max(np.where(cross & (i < ipk), i, -1), axis=0)
        after = np.min(np.where(cross & (i >= ipk), i, n), axis=0)
        ok = (before >= 0) & (after < n - 1) & (peak_v > 0.0)
        bi, ai = np.clip(before, 0, n - 2), np.clip(after, 0, n - 2)

        def t_cross(k):
            xa, xb = x[k, cols], x[k + 1, cols]
            den = np.where(xa - xb == 0.0, 1.0, xa - xb)
            return k + xa / den

        half = (t_cross(ai) - t_cross(bi)) / fs
        with np.errstate(divide="ignore", invalid="ignore"):
            fz = 0.5 / half
        freq = np.where(ok & (half > 0.0), fz, freq)
    freq = np.where(peak_v > 0.0, freq, np.nan)
    return peak_v.reshape(shape), freq.reshape(shape)


def velocity_level(v_rms, v_ref: float = FTA_V_REF) -> np.ndarray:
    """Velocity level ``20 log10(v_rms / v_ref)`` [dB].

    Parameters
    ----------
    v_rms
        RMS velocity [m/s].
    v_ref
        Reference velocity [m/s]; default the FTA reference 1e-6 in/s (VdB).

    Returns
    -------
    numpy.ndarray
        Level in dB (``-inf`` for zero velocity).
    """
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.asarray(v_rms, dtype=float) / v_ref)


def fta_vdb(v, fs: float, *, tau: float = TAU_SLOW, averaging: str = "exponential",
            axis: int = 0) -> np.ndarray:
    """FTA vibration velocity level L_v [VdB] of the maximum 1 s RMS velocity.

    Parameters
    ----------
    v
        Velocity [m/s] (unweighted).
    fs
        Sample rate [Hz].
    tau
        Averaging time [s]: the exponential time constant, or the rectangular window.
    averaging
        ``"exponential"`` (default: running RMS with time constant ``tau``, as the "slow"
        setting of vibration meters) or ``"linear"`` (sliding rectangular window).
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        ``20 log10(max_t v_rms(t) / 1e-6 in/s)`` per channel.
    """
    if averaging == "exponential":
        v_run = running_rms(v, fs, tau, axis=axis)
    elif averaging == "linear":
        v_run = linear_running_rms(v, fs, tau, axis=axis)
    else:
        raise ValueError(f"averaging = {averaging!r}: allowed are 'exponential' and 'linear'")
    return velocity_level(np.max(v_run, axis=axis))


def kb_f(v, fs: float, *, tau: float = TAU_FAST, band_limit: bool = True,
         axis: int = 0) -> np.ndarray:
    """DIN 4150-2 KB_F(t): running RMS (τ = 0.125 s) of the KB-weighted velocity.

    Parameters
    ----------
    v
        Velocity (DIN 4150-2 uses mm/s; the unit is kept).
    fs
        Sample rate [Hz].
    tau
        Time constant [s].
    band_limit
        Apply the 1–80 Hz band limits of :func:`~railvib_hpc.assess.weighting.kb_response`.
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        KB_F(t), same shape as ``v``.
    """
    return running_rms(weight_kb(v, fs, axis=axis, band_limit=band_limit), fs, tau, axis=axis)


def kb_fmax(v, fs: float, *, tau: float = TAU_FAST, band_limit: bool = True,
            axis: int = 0) -> np.ndarray:
    """DIN 4150-2 KB_Fmax = max_t KB_F(t), per channel (unit of ``v``).

    Parameters
    ----------
    v
        Velocity.
    fs
        Sample rate [Hz].
    tau
        Time constant [s].
    band_limit
        Apply the 1–80 Hz band limits.
    axis
        Time axis.

    Returns
    -------
    numpy.ndarray
        KB_Fmax per channel.
    """
    return np.max(kb_f(v, fs, tau=tau, band_limit=band_limit, axis=axis), axis=axis)


def kb_ftm(kb_f_history, fs: float, *, cycle: float = 30.0,
           axis: int = 0) -> tuple[np.ndarray, int]:
    """DIN 4150-2 KB_FTm: quadratic mean of the maxima of KB_F in 30 s cycles.

    Parameters
    ----------
    kb_f_history
        KB_F(t) from :func:`kb_f`.
    fs
        Sample rate [Hz].
    cycle
        Cycle length [s] (30 s in DIN 4150-2).
    axis
        Time axis.

    Returns
    -------
    kb_ftm : numpy.ndarray
        ``sqrt(mean_i KB_FTi²)`` per channel, KB_FTi the maximum in cycle i (a last,
        incomplete cycle counts as a cycle).
    n_cycles : int
        Number of cycles, so the record stands for ``n_cycles · cycle`` seconds of exposure.
    """
    x, fs = _prep(kb_f_history, fs, axis)
    w = max(1, int(round(cycle * fs)))
    n_cycles = -(-x.shape[0] // w)
    pad = n_cycles * w - x.shape[0]
    xp = np.concatenate([x, np.zeros((pad,) + x.shape[1:])], axis=0)
    maxima = np.max(xp.reshape((n_cycles, w) + x.shape[1:]), axis=1)
    return np.sqrt(np.mean(maxima**2, axis=0)), int(n_cycles)
