"""Free-field metrics of the probe lines against analytic answers (issue 28, item 4)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from railvib_hpc.assess.free_field import (
    format_free_field,
    free_field_metrics,
    free_field_summary,
    velocity_level_db,
)

A = 2e-3                       # amplitude [m/s]
FS = 1000.0


def _vertical(t, signal):
    v = np.zeros((t.size, 1, 3))
    v[:, 0, 2] = signal
    return v


@pytest.mark.parametrize("f", [10.0, 1000.0 * 10.0 ** (-12.0 / 10.0)])   # 10 Hz, 63.1 Hz
def test_a_sinusoid_at_a_band_centre_is_a_over_root_2_in_that_band_only(f):
    """10 Hz falls on an FFT bin of the 10 s record (exact), 63.096 Hz between two (its
    leakage stays in the band)."""
    t = np.arange(0.0, 10.0, 1.0 / FS)
    m = free_field_metrics(t, _vertical(t, A * np.sin(2 * np.pi * f * t)))
    band = int(np.argmin(abs(m["centre_hz"] - f)))
    assert m["band_rms_vertical"][band, 0] == pytest.approx(A / np.sqrt(2), rel=1e-4)
    others = np.delete(m["band_rms_vertical"][:, 0], band)
    assert others.max() < 0.01 * A
    assert m["band_rms_resultant"][band, 0] == pytest.approx(A / np.sqrt(2), rel=1e-4)
    assert m["ppv_vertical"][0] == pytest.approx(A, rel=1e-3)
    assert m["ppv_frequency_hz"][0] == pytest.approx(f, rel=0.02)
    assert list(m["nominal_hz"][[0, -1]]) == [1.0, 80.0] and m["nominal_hz"].size == 20


def test_the_running_rms_of_a_stationary_sinusoid_is_a_over_root_2():
    """Slow exponential averaging (tau = 1 s): after 20 tau the mean square ripples by
    1/(4 pi f tau) = 0.2 % at 40 Hz about A^2/2."""
    t = np.arange(0.0, 20.0, 1.0 / FS)
    m = free_field_metrics(t, _vertical(t, A * np.sin(2 * np.pi * 40.0 * t)))
    assert m["rms_max_vertical"][0] == pytest.approx(A / np.sqrt(2), rel=2e-3)
    assert m["rms_max_vertical"][0] >= A / np.sqrt(2)


def test_a_burst_shorter_than_the_window_rises_to_its_known_value():
    """A 0.25 s, 40 Hz burst: the running mean square reaches (A^2/2)(1 - e^(-T/tau)) at
    its end, then decays."""
    t = np.arange(0.0, 3.0, 1.0 / FS)
    burst = 0.25
    m = free_field_metrics(t, _vertical(t, np.where(t < burst - 1e-12,
                                                    A * np.sin(2 * np.pi * 40.0 * t), 0.0)))
    expected = A / np.sqrt(2) * np.sqrt(1.0 - np.exp(-burst / 1.0))
    assert m["rms_max_vertical"][0] == pytest.approx(expected, rel=2e-3)
    assert m["t_rms_max_vertical"][0] == pytest.approx(burst, abs=1.0 / 40.0)


def test_the_resultant_of_a_circular_motion_is_its_radius():
    """v = A (cos, 0, sin): |v| = A at every instant, both components A/sqrt(2) RMS."""
    t = np.arange(0.0, 20.0, 1.0 / FS)
    w = 2 * np.pi * 25.0            # 40 samples a period: the peaks are samples
    v = np.stack([A * np.cos(w * t), 0 * t, A * np.sin(w * t)], axis=1)[:, None, :]
    m = free_field_metrics(t, np.concatenate([v, 0.5 * v], axis=1))   # two probes at once
    assert m["ppv_resultant"] == pytest.approx([A, A / 2], rel=1e-9)
    assert m["ppv_vertical"] == pytest.approx([A, A / 2], rel=1e-3)
    assert m["rms_max_resultant"] == pytest.approx([A, A / 2], rel=1e-3)
    band = int(np.argmin(abs(m["nominal_hz"] - 25.0)))
    assert m["band_rms_resultant"][band] == pytest.approx([A, A / 2], rel=1e-6)


def test_levels_are_re_one_nanometre_per_second():
    assert velocity_level_db([1e-6, 1e-9]).tolist() == pytest.approx([60.0, 0.0])
    assert np.isnan(velocity_level_db(0.0))


def _hist(t, vz, role):
    v = np.zeros((t.size, 3))
    v[:, 2] = vz
    return {"t": t, "velocity": v, "acceleration": v, "coords": np.array([13.8, -5.0, 4.8]),
            "role": role}


def test_the_summary_takes_the_free_field_probes_and_is_json():
    """Only free-field probes; a user probe of that role gets |y| as its distance; bands
    narrower than the record's resolution (1 s: 1 Hz) have no value, not NaN."""
    t = np.arange(0.0, 1.0, 1.0 / FS)
    hist = {"slab1": _hist(t, A * np.sin(2 * np.pi * 25 * t), "floor"),
            "user_1": _hist(t, A * np.sin(2 * np.pi * 25 * t), "free_field")}
    out = free_field_summary(hist)
    assert list(out["probes"]) == ["user_1"]
    p = out["probes"]["user_1"]
    assert p["distance"] == 5.0 and p["line"] is None
    assert p["ppv_vertical"] == pytest.approx(A, rel=1e-3)
    assert out["bands"]["n_bins"][1] == 0 and p["band_rms_vertical"][1] is None   # 1.25 Hz
    k = out["bands"]["nominal_hz"].index(25.0)
    assert p["band_level_vertical_db"][k] == pytest.approx(20 * np.log10(A / np.sqrt(2) / 1e-9),
                                                           abs=0.05)
    json.dumps(out, allow_nan=False)
    text = format_free_field(out)
    assert "user_1" in text and "dB re 1e-9 m/s" in text
    assert free_field_summary({"slab1": hist["slab1"]}) == {}
