"""The modal path with supported track ends (``track.ends = 'supported'``, issue 28 item 3).

The rail continues beyond the soil box on fitted springs and graded dashpots; the modal
path (``railvib run``, its modal and mbs stages) takes it with ``modal.damping = 'full'``
(the dashpots projected on the modes) and fits the springs with the same function as the
full-order path (:func:`railvib_hpc.model.petsc.fit_track_ends`). Checked against the
direct path on the same tiny model, on the rank count the test runs on.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "transient"))
from transient_cases import BASELINE, run_transient_only

from railvib_hpc.cli import run

comm = MPI.COMM_WORLD
#: The tiny thesis model with supported ends; 40 modes (10.9-21.4 Hz) and the static
#: correction, which carries the rail's local deflection that 40 modes cannot.
CASE = [a for s in ("mesh.refinement=0.25", "output.dt=0.002", "output.stress_times=[]",
                    "track.ends=supported", "modal.damping=full", "modal.n_modes=40",
                    "mbs.static_correction=true", "transient.checkpoint_interval=0")
        for a in ("--set", s)]
#: Sections along the 27.6 m of modelled rail: the entry support, the box's first bay
#: region, its middle, its last region and the exit support [m].
SECTIONS = ((0.3, 3.0), (3.0, 6.0), (6.0, 21.6), (21.6, 24.6), (24.6, 27.3))
#: Largest difference of the rail deflection under the wheel, modal (40 modes + static
#: correction) against direct, over the largest direct deflection: measured 0.009-0.066
#: per section on one rank (modal truncation; the static correction is exact statically).
DEFLECTION_RTOL = 0.10
#: The sections' largest deflections: measured within 0.3-2.4 %.
PEAK_RTOL = 0.05


def _under_wheel(path: Path) -> tuple[np.ndarray, np.ndarray]:
    with h5py.File(path, "r") as f:
        return f["wheels/x"][:, 0], f["wheels/rail_displacement"][:, 0]


def _fit_line(text: str) -> str:
    return re.search(r"track ends: supported, .*? N/m per rail", text).group(0)


@pytest.mark.slow
@pytest.mark.mpi
def test_the_modal_path_with_supported_ends_matches_the_direct_path(shared_tmp, capsys):
    """``railvib modal`` + ``mbs`` and ``railvib transient`` (direct) on the same model: the same
    fitted springs, and the rail's deflection under the leading wheel within
    :data:`DEFLECTION_RTOL` over the whole modelled rail, the supports included. Then a
    changed ``damping.f2`` recomputes only ``modal_damping.h5`` (reused modes): its
    dashpot part, which the fitted springs set, is the first run's."""
    out = shared_tmp / f"ends_{comm.size}"
    # (modal and mbs: what the comparison reads, without the fields and the report)
    assert run(["modal", str(BASELINE), "--out", str(out / "modal"), *CASE]) == 0
    modal_log = capsys.readouterr().out
    assert run(["mbs", str(BASELINE), "--out", str(out / "modal"), *CASE]) == 0
    capsys.readouterr()
    run_transient_only(out / "direct", CASE[1::2])        # (no report either)
    direct_log = capsys.readouterr().out
    if comm.rank == 0:                        # the log is rank 0's
        assert _fit_line(modal_log) == _fit_line(direct_log)

    xm, wm = _under_wheel(out / "modal" / "mbs.h5")
    xd, wd = _under_wheel(out / "direct" / "transient.h5")
    grid = np.arange(SECTIONS[0][0], SECTIONS[-1][1], 0.05)
    a, b = np.interp(grid, xm, wm), np.interp(grid, xd, wd)
    scale = np.abs(b).max()
    for lo, hi in SECTIONS:
        m = (grid >= lo) & (grid < hi)
        assert np.abs(a[m] - b[m]).max() <= DEFLECTION_RTOL * scale, (lo, hi)
        assert abs(a[m].min() / b[m].min() - 1) <= PEAK_RTOL, (lo, hi)

    with h5py.File(out / "modal" / "modal_damping.h5", "r") as f:
        dashpots = f["dashpots"][()]
    assert np.abs(dashpots).max() > 0
    assert run(["modal", str(BASELINE), "--out", str(out / "modal"), *CASE,
                "--set", "damping.f2=60.0"]) == 0
    rerun = capsys.readouterr().out
    if comm.rank == 0:
        assert "reusing" in rerun and _fit_line(rerun) == _fit_line(modal_log)
    with h5py.File(out / "modal" / "modal_damping.h5", "r") as f:
        again = f["dashpots"][()]
    assert np.allclose(again, dashpots, rtol=1e-9, atol=1e-12 * np.abs(dashpots).max())
