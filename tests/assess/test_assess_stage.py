"""The assess stage's own pieces: wave speeds, arrival detection, inputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from railvib_hpc.assess.stage import AssessStageError, read_probes, wave_arrival, wave_speeds
from railvib_hpc.config import load_case
from railvib_hpc.problem import Problem

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"


def test_subgrade_wave_speeds_match_the_reference():
    c_p, c_s = wave_speeds(Problem.from_case(load_case(BASELINE)))
    assert c_p == pytest.approx(346.58, abs=0.005)       # benchmarks.md section 1
    assert c_s == pytest.approx(212.24, abs=0.005)
    # the thesis's basement-wall distance 20.2 m: t_P = 0.058 s, t_S = 0.095 s
    assert 20.2 / c_p == pytest.approx(0.058, abs=5e-4)
    assert 20.2 / c_s == pytest.approx(0.095, abs=5e-4)


def test_wave_arrival_finds_the_onset_of_a_delayed_burst():
    t = np.arange(0.0, 1.0, 1e-3)
    onset = 0.3466
    a = np.zeros((t.size, 3))
    late = t >= onset
    a[late, 1] = np.sin(2 * np.pi * 40 * (t[late] - onset)) * np.exp(-(t[late] - onset) / 0.1)
    # 10 % of the peak is reached in the first rising quarter period of the 40 Hz burst
    expected = onset + np.arcsin(0.1 / np.abs(a[:, 1]).max()) / (2 * np.pi * 40)
    assert wave_arrival(t, a, 0.1, 0.1) == pytest.approx(expected, abs=1.5e-3)
    # nothing after the entry time: NaN
    assert np.isnan(wave_arrival(t, np.zeros((t.size, 3)), 0.1, 0.1))


def test_missing_probes_file_is_a_clear_error(tmp_path):
    with pytest.raises(AssessStageError, match="run 'railvib reconstruct' first"):
        read_probes(tmp_path / "probes.h5")
