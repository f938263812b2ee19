"""The ``railvib mbs`` stage on the coarse thesis model: mbs.h5, plots, reuse, errors, 2 ranks."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from railvib_hpc.cli import run
from railvib_hpc.constants import STANDARD_GRAVITY

BASELINE = Path(__file__).resolve().parents[2] / "jobs" / "thesis_baseline.toml"
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=12"]


@pytest.fixture(scope="module")
def modal_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("mbs_stage")
    assert run(["modal", str(BASELINE), *COARSE, "--set", "mbs.static_correction=true",
                "--out", str(out)]) == 0
    return out


def _mbs(out: Path, *sets: str) -> int:
    args = ["mbs", str(BASELINE), *COARSE, "--out", str(out)]
    for s in sets:
        args += ["--set", s]
    return run(args)


def test_wheelset_passage_writes_mbs_h5_and_plots(modal_dir, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(modal_dir, out)
    assert _mbs(out) == 0
    with h5py.File(out / "mbs.h5", "r") as f:
        assert f.attrs["complete"] == 1
        t = f["time"][()]
        x = f["wheels/x"][()]
        force = f["wheels/contact_force"][()]
        q = f["modal/q"][()]
        stats = json.loads(f.attrs["stats"])
        assert f["vehicle/y"].shape == (t.size, 3)
        assert f["modal/q_ddot"].shape == q.shape == (t.size, 12)
        assert "static" not in f
    # entry on the rigid rail at x_start = 0, exit when the wheel reaches the rail end
    assert x[0, 0] == pytest.approx(0.0)
    assert x[-1, 0] == pytest.approx(27.6, abs=30.0 * stats["dt"])
    # the wheelset's weight alone: 1568 kg * g / 2 = 7688 N per wheel (less 0.5 N: the
    # suspension springs, 25 kN/m, stretch by the 20 um Hertz penetration)
    assert force[0] == pytest.approx(0.5 * 1568 * STANDARD_GRAVITY - 25e3 * 20.0e-6, rel=2e-5)
    assert np.allclose(stats["mean_contact_force"], 0.5 * 1568 * STANDARD_GRAVITY, rtol=0.01)
    assert stats["loss_of_contact_steps"] == 0
    for name in ("contact_force", "wheel_displacement", "rail_deflection"):
        png = out / f"mbs_{name}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # a rerun reuses the file; a changed speed recomputes it
    mtime = (out / "mbs.h5").stat().st_mtime_ns
    assert _mbs(out) == 0
    assert (out / "mbs.h5").stat().st_mtime_ns == mtime
    assert _mbs(out, "vehicle.speed=20") == 0
    with h5py.File(out / "mbs.h5", "r") as f:
        assert f["wheels/x"][-1, 0] - f["wheels/x"][0, 0] == pytest.approx(
            20.0 * f["time"][-1], rel=1e-12)


def test_static_correction_softens_the_track(modal_dir, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(modal_dir, out)
    assert _mbs(out, "vehicle.speed=1", "vehicle.x_start=12", "vehicle.x_end=12.3") == 0
    with h5py.File(out / "mbs.h5", "r") as f:
        w_modal = f["wheels/rail_displacement"][()].min()
    assert _mbs(out, "vehicle.speed=1", "vehicle.x_start=12", "vehicle.x_end=12.3",
                "mbs.static_correction=true") == 0
    with h5py.File(out / "mbs.h5", "r") as f:
        w_full = f["wheels/rail_displacement"][()].min()
        g = f["static/g"][()]
        assert f["static/q_shift"].shape == f["modal/q"].shape
    with h5py.File(out / "static.h5", "r") as f:
        x_rr = f["static/rail_flexibility"][()]
    # 12 modes miss most of the local rail flexibility; the correction restores it
    assert w_full < 1.5 * w_modal < 0.0
    # the rail-DOF loads carry the wheel forces (Hermite: sum of the w-loads = -sum F)
    assert g[:, 0::2].sum(axis=1) == pytest.approx(-2 * 0.5 * 1568 * STANDARD_GRAVITY, rel=0.02)
    assert np.allclose(x_rr, x_rr.T) and np.all(np.diag(x_rr) >= 0)


def test_moving_force_and_train_and_irregularity(modal_dir, tmp_path):
    out = tmp_path / "run"
    shutil.copytree(modal_dir, out)
    assert _mbs(out, "vehicle.type=moving_force", "vehicle.axle_offsets=[0, -2.5]") == 0
    with h5py.File(out / "mbs.h5", "r") as f:
        assert f["wheels/contact_force"].shape[1] == 4
        assert np.allclose(f["wheels/contact_force"][()], 0.5 * 1568 * STANDARD_GRAVITY)
    assert _mbs(out, "vehicle.type=vehicle", "irregularity.type=fra",
                "irregularity.track_class=6", "vehicle.speed=40") == 0
    with h5py.File(out / "mbs.h5", "r") as f:
        force = f["wheels/contact_force"][()]
        assert f["vehicle/y"].shape[1] == 17 and force.shape[1] == 8
    # a random profile makes the wheel forces fluctuate about the static load
    assert force.max() > 1.05 * force[0].max()


def test_errors_are_clear(tmp_path, capsys):
    assert _mbs(tmp_path) == 2
    assert "modes.h5 not found: run 'railvib modal' first" in capsys.readouterr().err


def test_mbs_needs_static_file(modal_dir, tmp_path, capsys):
    out = tmp_path / "run"
    shutil.copytree(modal_dir, out)
    (out / "static.h5").unlink()
    assert _mbs(out, "mbs.static_correction=true") == 2
    assert "static.h5" in capsys.readouterr().err


def test_a_contact_newton_failure_stops_the_passage_in_one_line(modal_dir, tmp_path,
                                                                failing_contact_newton,
                                                                capsys):
    """The contact Newton made to fail at its tenth call: exit code 3 (not a result, not a
    bug), one line with the time, the position and what to change, no mbs.h5."""
    failing_contact_newton(10)
    out = tmp_path / "run"
    shutil.copytree(modal_dir, out)
    capsys.readouterr()
    assert _mbs(out) == 3
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1, err
    assert err[0].startswith("railvib mbs: error: the modal passage failed at t = ")
    assert "did not converge in 50 iterations" in err[0] and "change: " in err[0]
    assert not (out / "mbs.h5").exists()
