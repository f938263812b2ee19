"""The thesis comparison's own numbers: Weyl counts, the thesis's clock, the far-wall probe."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.assess.thesis import (
    THESIS,
    format_thesis_table,
    thesis_clock_arrival,
    weyl_count,
)
from railvib_hpc.config import load_case
from railvib_hpc.mesh.layout import build_layout

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"


def test_weyl_count_of_the_thesis_domain():
    case = load_case(BASELINE)
    # soil box 21.6 x 37.35 x 4.8 m, c_P 346.58, c_S 212.24 m/s
    volume = 21.6 * 37.35 * 4.8
    c_p, c_s = 346.58, 212.24
    expected = 4 * math.pi / 3 * volume * 57.87**3 * (1 / c_p**3 + 2 / c_s**3)
    assert weyl_count(case, 57.87) == pytest.approx(expected, rel=1e-4)
    assert 730 < weyl_count(case, 57.87) < 736          # ~2.4x the thesis's 300
    assert weyl_count(case, 44.16) == pytest.approx(326, abs=1)
    # N ~ f^3
    assert weyl_count(case, 2 * 30.0) == pytest.approx(8 * weyl_count(case, 30.0), rel=1e-12)


def test_arrival_on_the_thesis_clock():
    """A burst that starts 0.06 s after the wheel enters the flexible rail (0.10 s on the
    thesis's clock at 30 m/s from x = 0) is detected at 0.16 s, the thesis's P arrival."""
    case = load_case(BASELINE)
    xyz = build_layout(case).probes["basement_wall_far"]
    t = np.arange(0.0, 0.4, 1e-4)
    a = np.zeros((t.size, 3))
    on = t >= 0.16
    a[on, 1] = np.sin(2 * np.pi * 20 * (t[on] - 0.16)) * np.exp(-(t[on] - 0.16) / 0.05)
    hist = {"basement_wall_far": {"t": t, "acceleration": a, "coords": np.array(xyz)}}
    arr = thesis_clock_arrival(case, hist)
    assert arr["t_entry"] == pytest.approx(0.1)
    assert arr["detected"] == pytest.approx(0.16, abs=2e-3)
    # 19.28 m from the nearer rail at the entry; 20.22 m from the far rail to the wall base
    assert arr["distance"] == pytest.approx(19.28, abs=0.01)
    assert arr["distance_far_rail"] == pytest.approx(20.2, abs=0.03)
    # the thesis's own arithmetic: 20.2 m / (0.16 - 0.10) s = 337 m/s, (0.20 - 0.10): 202
    assert 20.2 / (THESIS["p_wave_arrival_basement_wall"] - 0.1) == pytest.approx(336.7, abs=0.1)
    assert 20.2 / (THESIS["s_wave_arrival_basement_wall"] - 0.1) == pytest.approx(202.0)
    # a run that starts elsewhere is shifted to the thesis's clock
    late = load_case(BASELINE, ["vehicle.x_start=1.5"])
    shifted = thesis_clock_arrival(late, {"basement_wall_far": {
        "t": t - 0.05, "acceleration": a, "coords": np.array(xyz)}})
    assert shifted["detected"] == pytest.approx(0.16, abs=2e-3)
    assert thesis_clock_arrival(case, {}) is None


def test_table_text_has_every_row_explained():
    rows = [{"quantity": "q", "thesis": "1", "railvib": "2", "explanation": "because 2"}]
    text = format_thesis_table(rows)
    assert "thesis:      1" in text and "explanation: because 2" in text
