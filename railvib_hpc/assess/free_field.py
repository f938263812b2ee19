"""Free-field metrics of the probe lines: PPV, the largest 1 s running RMS, 1/3-octave spectra.

Every probe of role ``free_field`` (the points of ``[[probes.line]]``,
:func:`railvib_hpc.site.line_probes`) is described, unweighted, by what a site survey
measures on the ground (DIN 45669-1 measurement chain, 1–80 Hz):

* **PPV**: ``max |v_z|`` (vertical, with its dominant frequency from the zero crossings
  round the peak, :func:`~railvib_hpc.assess.metrics.ppv`) and ``max |v|`` (resultant,
  the magnitude of the velocity vector).
* **Largest running RMS, 1 s**: the exponential running RMS with the time constant
  τ = 1 s (the "slow" time weighting S of DIN 45669-1 and IEC 61672-1, ISO 2631-1:1997
  eq. 8, to which ISO 2631-2:2003 refers; :func:`~railvib_hpc.assess.metrics.running_rms`,
  the signal zero before the record), vertical and resultant (the square root of the
  sum of the components' running mean squares: the filter is linear in v²). *Choice:*
  exponential rather than a 1 s sliding window, because it is what a vibration meter's
  "slow" setting shows and what the assessment's MTVV and FTA levels already use. For a
  stationary sinusoid of amplitude A it is A/√2; for a burst of duration T it rises to
  (A/√2)·√(1 - e^(-T/τ)).
* **One-third-octave velocity spectrum**: band RMS over the whole record in the base-10
  bands of IEC 61260-1 with nominal centres 1 to 80 Hz
  (:func:`~railvib_hpc.assess.weighting.third_octave_rms`: the power spectrum of the
  record summed per band, Parseval-exact), vertical and resultant, in m/s and as the
  velocity level ``L_v = 20 lg(v_rms / v_0)`` dB re v_0 = 1e-9 m/s (ISO 1683:2015). The
  band RMS is over the whole record, so a record much longer than the passage lowers it
  (by 10 lg of the ratio of durations); bands narrower than the record's frequency
  resolution ``1 / duration`` hold no FFT bin and have no value (``None``).

All arrays are batched over the probes (one call for all probes of a run).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from . import metrics
from .weighting import third_octave_rms

#: Reference velocity of velocity levels [m/s] (ISO 1683:2015, 1 nm/s).
V_REF_ISO1683 = 1e-9
#: Band of the spectra [Hz]: nominal one-third-octave centres from 1 to 80 Hz (the
#: measurement band of DIN 45669-1 and of DIN 4150-2).
FREE_FIELD_FMIN, FREE_FIELD_FMAX = 1.0, 80.0
#: Largest relative variation of the time step of a record (as the standards' check).
_UNIFORM = 1e-5


def sample_rate(t) -> float:
    """The sample rate [Hz] of uniformly sampled times ``t``.

    Raises
    ------
    ValueError
        For fewer than 2 samples, non-increasing or non-uniform times.
    """
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError(f"t has shape {t.shape}: need a 1-D array of at least 2 times")
    dt = np.diff(t)
    step = (t[-1] - t[0]) / (t.size - 1)
    if not step > 0 or np.max(np.abs(dt - step)) > _UNIFORM * step:
        raise ValueError("t must be strictly increasing and uniformly sampled")
    return 1.0 / step


def free_field_metrics(t, velocity) -> dict[str, np.ndarray]:
    """PPV, the largest 1 s running RMS and the one-third-octave spectrum of velocities.

    Parameters
    ----------
    t
        (nt,) uniformly sampled times [s].
    velocity
        (nt, p, 3) velocities of ``p`` probes [m/s] (x, y, z; a (nt, 3) array is one probe).

    Returns
    -------
    dict
        (p,) arrays ``ppv_vertical``, ``ppv_frequency_hz`` (of the vertical peak; NaN at
        rest), ``ppv_resultant``, ``rms_max_vertical``, ``rms_max_resultant`` and the
        times of those maxima ``t_rms_max_vertical``, ``t_rms_max_resultant``; the bands
        ``nominal_hz``, ``centre_hz``, ``n_bins`` (n_b,) and the spectra
        ``band_rms_vertical``, ``band_rms_resultant`` (n_b, p) [m/s].

    Examples
    --------
    >>> t = np.arange(0.0, 10.0, 1e-3)
    >>> v = np.zeros((t.size, 1, 3))
    >>> v[:, 0, 2] = 2e-3 * np.sin(2 * np.pi * 10.0 * t)      # 2 mm/s at 10 Hz
    >>> m = free_field_metrics(t, v)
    >>> round(float(m["ppv_vertical"][0]) * 1e3, 3), round(float(m["ppv_frequency_hz"][0]), 2)
    (2.0, 10.0)
    >>> band = list(m["nominal_hz"]).index(10.0)
    >>> round(float(m["band_rms_vertical"][band, 0]) * 1e3, 4)   # A / sqrt(2)
    1.4142
    """
    fs = sample_rate(t)
    v = np.asarray(velocity, dtype=float)
    if v.ndim == 2:
        v = v[:, None, :]
    if v.ndim != 3 or v.shape[0] != np.size(t) or v.shape[2] != 3:
        raise ValueError(f"velocity has shape {v.shape}: need (nt, p, 3) with nt = {np.size(t)}")
    t = np.asarray(t, dtype=float)
    vz = v[:, :, 2]
    ppv_z, f_z = metrics.ppv(vz, fs)
    run = metrics.running_rms(v, fs, metrics.TAU_SLOW)               # (nt, p, 3)
    run_res = np.sqrt(np.sum(run * run, axis=2))
    i_z, i_res = np.argmax(run[:, :, 2], axis=0), np.argmax(run_res, axis=0)
    cols = np.arange(v.shape[1])
    spec = third_octave_rms(v, fs, fmin=FREE_FIELD_FMIN, fmax=FREE_FIELD_FMAX)
    return {
        "ppv_vertical": ppv_z, "ppv_frequency_hz": f_z,
        "ppv_resultant": metrics.peak(np.linalg.norm(v, axis=2)),
        "rms_max_vertical": run[i_z, cols, 2], "t_rms_max_vertical": t[i_z],
        "rms_max_resultant": run_res[i_res, cols], "t_rms_max_resultant": t[i_res],
        "nominal_hz": spec.bands.nominal, "centre_hz": spec.bands.centre,
        "n_bins": spec.n_bins, "band_rms_vertical": spec.rms[:, :, 2],
        "band_rms_resultant": np.sqrt(np.sum(spec.rms ** 2, axis=2)),
    }


def velocity_level_db(v_rms) -> np.ndarray:
    """``20 lg(v_rms / 1e-9 m/s)`` [dB re 1 nm/s] (NaN for no motion).

    Examples
    --------
    >>> velocity_level_db([1e-6, 0.0]).tolist()
    [60.0, nan]
    """
    v = np.asarray(v_rms, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(v > 0, 20.0 * np.log10(np.where(v > 0, v, 1.0) / V_REF_ISO1683),
                        np.nan)


def _json(x) -> Any:
    """A float or a list of them with NaN/inf as None (JSON)."""
    a = np.asarray(x, dtype=float)
    if a.ndim == 0:
        return float(a) if np.isfinite(a) else None
    return [float(v) if np.isfinite(v) else None for v in a]


def free_field_summary(histories: Mapping[str, Mapping[str, Any]],
                       lines: Mapping[str, Any] | None = None) -> dict[str, dict[str, Any]]:
    """The free-field metrics of every probe of role ``free_field`` (JSON-ready, SI).

    Parameters
    ----------
    histories
        Probe name -> ``{"t", "velocity" (nt, 3), "coords", "role"}`` (``probes.h5``).
    lines
        Probe name -> :class:`railvib_hpc.site.LineProbe` (its line, distance and side);
        a free-field probe without one (a user probe of that role) gets its distance from
        its coordinates (``|y|``) and no line.

    Returns
    -------
    dict
        ``{"bands": {...}, "probes": {name: {...}}}``, empty when no probe is free-field.
        Bands with no FFT bin in the record have ``None`` values.
    """
    names = [n for n, h in histories.items() if h.get("role") == "free_field"]
    if not names:
        return {}
    lines = lines or {}
    groups: dict[tuple, list[str]] = {}           # probes sharing one time axis
    for n in names:
        t = np.asarray(histories[n]["t"], dtype=float)
        groups.setdefault((t.size, float(t[0]), float(t[-1])), []).append(n)
    probes: dict[str, dict[str, Any]] = {}
    bands: dict[str, Any] = {}
    for group in groups.values():
        t = histories[group[0]]["t"]
        m = free_field_metrics(t, np.stack([histories[n]["velocity"] for n in group], axis=1))
        empty = m["n_bins"] == 0
        bands = {"nominal_hz": _json(m["nominal_hz"]), "centre_hz": _json(m["centre_hz"]),
                 "n_bins": [int(b) for b in m["n_bins"]], "record_s": float(t[-1] - t[0])}
        for i, n in enumerate(group):
            lp = lines.get(n)
            xyz = np.asarray(histories[n]["coords"], dtype=float)
            spectra = {}
            for key in ("vertical", "resultant"):
                rms = np.where(empty, np.nan, m[f"band_rms_{key}"][:, i])
                spectra[f"band_rms_{key}"] = _json(rms)
                spectra[f"band_level_{key}_db"] = _json(velocity_level_db(rms))
            probes[n] = {
                "line": getattr(lp, "line", None), "side": getattr(lp, "side", None),
                "distance": float(lp.distance) if lp is not None else float(abs(xyz[1])),
                "coords": _json(xyz),
                **{k: _json(m[k][i]) for k in ("ppv_vertical", "ppv_frequency_hz",
                                                "ppv_resultant", "rms_max_vertical",
                                                "t_rms_max_vertical", "rms_max_resultant",
                                                "t_rms_max_resultant")},
                **spectra}
    return {"unit": "m/s", "level_reference": "dB re 1e-9 m/s (ISO 1683)",
            "running_rms": "exponential, time constant 1 s (slow, DIN 45669-1 / ISO 2631-1 "
                           "eq. 8), maximum over the record",
            "bands": bands, "probes": probes}


def format_free_field(summary: Mapping[str, Any]) -> str:
    """The free-field table (PPV and largest 1 s RMS in mm/s) and the vertical
    one-third-octave levels per probe (dB re 1e-9 m/s)."""
    if not summary:
        return ""
    probes = summary["probes"]

    def mm(x):
        return f"{x * 1e3:9.4g}" if x is not None else f"{'-':>9s}"

    lines = ["free field (probe lines), unweighted velocity; PPV = max |v|, RMS_S = largest "
             "exponential 1 s running RMS (DIN 45669-1 'slow'):",
             f"  {'probe':18s} {'d [m]':>7s} {'PPV z':>9s} {'f_z [Hz]':>9s} {'PPV res':>9s} "
             f"{'RMS_S z':>9s} {'RMS_S res':>9s}   [mm/s]"]
    for name, p in probes.items():
        f = p["ppv_frequency_hz"]
        lines.append(f"  {name:18s} {p['distance']:7.2f} {mm(p['ppv_vertical'])} "
                     + (f"{f:9.2f}" if f is not None else f"{'-':>9s}")
                     + f" {mm(p['ppv_resultant'])} {mm(p['rms_max_vertical'])} "
                       f"{mm(p['rms_max_resultant'])}")
    bands = summary["bands"]
    lines.append(f"one-third-octave vertical velocity levels, dB re 1e-9 m/s (RMS over the "
                 f"record of {bands['record_s']:.3g} s; '-': no FFT bin in the band):")
    names = list(probes)
    lines.append(f"  {'f [Hz]':>7s} " + " ".join(f"{n[:12]:>12s}" for n in names))
    for b, f in enumerate(bands["nominal_hz"]):
        cells = [probes[n]["band_level_vertical_db"][b] for n in names]
        lines.append(f"  {f:7.3g} " + " ".join(f"{c:12.1f}" if c is not None else f"{'-':>12s}"
                                               for c in cells))
    return "\n".join(lines)
