"""The fast modal path with non-proportional damping (issue 12, step 4): Phi^T C Phi and the
coupled modal integration, against the direct solution."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from wave_cases import Model, column_mesh, smooth_pulse, soil_case

from railvib_hpc.cli import run
from railvib_hpc.mbs.propagator import coupled_propagator, modal_propagator

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"


def _dense(A) -> np.ndarray:
    import scipy.sparse as sp

    ip, ix, v = A.getValuesCSR()
    return sp.csr_matrix((v, ix, ip), shape=A.getSize()).toarray()


def test_coupled_propagator_with_a_diagonal_matrix_is_the_diagonal_one():
    om = np.linspace(5.0, 400.0, 30)
    zeta = np.linspace(0.01, 0.2, 30)
    p, c = modal_propagator(om, zeta, 1e-3), coupled_propagator(om, np.diag(2 * zeta * om), 1e-3)
    for name in ("a_qq", "a_qv", "a_vq", "a_vv", "b_q0", "b_q1", "b_v0", "b_v1"):
        full, diag = getattr(c, name), getattr(p, name)
        assert np.abs(np.diag(full) - diag).max() <= 1e-11 * np.abs(diag).max(), name
        assert np.abs(full - np.diag(np.diag(full))).max() == 0.0, name


def test_all_modes_with_the_full_damping_matrix_reproduce_the_direct_solution():
    """A soil column on an absorbing base (dashpots + springs) with Rayleigh damping: the
    dashpots make C non-proportional. With every mode and D = Phi^T C Phi the coupled modal
    equations give the direct solution; the diagonal of D alone does not."""
    from railvib_hpc.modal.projection import project

    nz, height, dt = 20, 10.0, 2e-4
    case = soil_case("boundary.base=absorbing", "boundary.virtual_thickness=10",
                     "damping.model=rayleigh", "modal.damping_ratio=0.02")
    model = Model(column_mesh(nz, height), case, {"all": ("ux", "uy")}, MPI.COMM_SELF, dt)
    k, m = _dense(model.K), _dense(model.M)
    from scipy.linalg import eigh

    lam, phi = eigh(k, m)
    omega = np.sqrt(lam)
    d = project(model.C, phi, MPI.COMM_SELF)
    assert np.abs(d - phi.T @ _dense(model.C) @ phi).max() < 1e-9 * np.abs(d).max()
    assert np.abs(d - np.diag(np.diag(d))).max() > 0.1 * np.abs(np.diag(d)).max()
    top = np.flatnonzero(np.isclose(model.mesh.points[:, 2], height))
    dofs = model.dofs(top, 2)
    duration, nt = 0.02, 400

    def force(n):
        return np.full(top.size, -250.0) * smooth_pulse(n * dt, duration)

    solver = model.solver(lambda n: (dofs, force(n)))
    st = model.state()
    direct = [0.0]
    for _ in range(nt):
        solver.step(st)
        direct.append(st.u[dofs[0]])
    solver.destroy()
    model.destroy()
    out = {}
    for name, damping in (("full", d), ("diagonal", np.diag(np.diag(d)))):
        prop = coupled_propagator(omega, damping, dt)
        q, v = np.zeros(omega.size), np.zeros(omega.size)
        hist = [0.0]
        for n in range(nt):
            q, v = prop.step(q, v, phi[dofs].T @ force(n), phi[dofs].T @ force(n + 1))
            hist.append(float(phi[dofs[0]] @ q))
        out[name] = np.array(hist)
    direct = np.array(direct)
    scale = np.abs(direct).max()
    # the trapezoidal rule's O(dt^2) phase error against the exact modal propagation
    assert np.abs(out["full"] - direct).max() < 2e-3 * scale
    assert np.abs(out["diagonal"] - direct).max() > 10 * np.abs(out["full"] - direct).max()


@pytest.mark.slow
def test_modal_stage_writes_the_projected_parts_and_mbs_integrates_them(tmp_path):
    args = ["--out", str(tmp_path), "--set", "mesh.refinement=0.25", "--set",
            "modal.n_modes=30", "--set", "modal.damping=full", "--set",
            "boundary.base=absorbing", "--set", "boundary.y_min=absorbing", "--set",
            "boundary.virtual_thickness=30", "--set", "vehicle.x_start=2.7", "--set",
            "vehicle.x_end=4.2"]
    assert run(["modal", str(BASELINE), *args]) == 0
    with h5py.File(tmp_path / "modal_damping.h5", "r") as f:
        names = set()
        f.visititems(lambda n, o: names.add(n) if hasattr(o, "shape") else None)
        assert {"dashpots", "pads", "mass/subgrade", "stiffness/subgrade"} <= names
        dash = f["dashpots"][()]
    assert dash.shape == (30, 30) and np.allclose(dash, dash.T)
    assert np.all(np.linalg.eigvalsh(dash) > -1e-9 * np.abs(dash).max())
    # a deleted parts file is rebuilt from the reused modes
    before = dash.copy()
    (tmp_path / "modal_damping.h5").unlink()
    assert run(["modal", str(BASELINE), *args]) == 0
    with h5py.File(tmp_path / "modal_damping.h5", "r") as f:
        assert np.abs(f["dashpots"][()] - before).max() <= 1e-10 * np.abs(before).max()
    assert run(["mbs", str(BASELINE), *args]) == 0
    with h5py.File(tmp_path / "mbs.h5", "r") as f:
        dm = f["modal/damping_matrix"][()]
        om = f["modal/omega"][()]
        zeta = f["modal/zeta"][()]
        assert dm.shape == (30, 30)
        assert zeta == pytest.approx(np.diag(dm) / (2 * om), rel=1e-12)
        assert np.all(np.isfinite(f["modal/q"][()]))


@pytest.mark.slow
def test_static_correction_with_full_damping_damps_the_residual_modes(tmp_path):
    """``modal.damping = 'full'`` with the static correction: the parts are projected on the
    modes and the deflated static fields, rebuilt the same from reused modes, and the
    multibody stage runs the modes with the residual modes (above the band), coupled."""
    args = ["--out", str(tmp_path), "--set", "mesh.refinement=0.25", "--set",
            "modal.n_modes=20", "--set", "modal.damping=full", "--set",
            "mbs.static_correction=true", "--set", "boundary.base=absorbing", "--set",
            "vehicle.x_start=2.7", "--set", "vehicle.x_end=4.2"]
    assert run(["modal", str(BASELINE), *args]) == 0
    with h5py.File(tmp_path / "static.h5", "r") as f:
        n_r = f["static/rail_flexibility"].shape[0]
        mass = f["static/residual_mass"][()]
    assert np.all(np.linalg.eigvalsh(mass) > -1e-9 * np.abs(mass).max())
    with h5py.File(tmp_path / "modal_damping.h5", "r") as f:
        dash = f["dashpots"][()]
    assert dash.shape == (20 + n_r, 20 + n_r)
    (tmp_path / "modal_damping.h5").unlink()
    assert run(["modal", str(BASELINE), *args]) == 0
    with h5py.File(tmp_path / "modal_damping.h5", "r") as f:
        again = f["dashpots"][()]
    assert np.abs(again - dash).max() <= 1e-8 * np.abs(dash).max()
    for n_modes in (20, 12):                     # all modes of the file, and fewer
        assert run(["mbs", str(BASELINE), *args, "--set", f"mbs.n_modes={n_modes}"]) == 0
        with h5py.File(tmp_path / "mbs.h5", "r") as f:
            om = f["modal/omega"][()]
            res_om = f["static/residual_omega"][()]
            assert f["modal/damping_matrix"].shape == (n_modes, n_modes)
            assert res_om.size > 0 and res_om.min() >= om.max()
            assert np.all(np.isfinite(f["static/g_ddot"][()]))
            force = f["wheels/contact_force"][()]
        assert np.all(np.isfinite(force)) and force.max() < 3 * force[0].max()


def test_modal_damping_file_is_a_stage_file(tmp_path, capsys):
    """``modal_damping.h5`` carries provenance: a changed ``[damping]`` recomputes it (the
    modes are reused), and ``mbs`` refuses one of other settings in one line, exit code 2."""
    args = ["--out", str(tmp_path), "--set", "mesh.refinement=0.25", "--set",
            "modal.n_modes=12", "--set", "modal.damping=full", "--set",
            "boundary.base=absorbing", "--set", "vehicle.x_start=2.7", "--set",
            "vehicle.x_end=4.2"]
    assert run(["modal", str(BASELINE), *args]) == 0
    with h5py.File(tmp_path / "modal_damping.h5", "r") as f:
        assert f.attrs["railvib_file"] == "modal_damping.h5" and f.attrs["complete"] == 1
        pads = f["pads"][()]
    capsys.readouterr()
    assert run(["modal", str(BASELINE), *args, "--set", "damping.f1=3.0"]) == 0
    out = capsys.readouterr().out
    assert f"reusing {tmp_path / 'modes.h5'}" in out
    assert f"recomputing {tmp_path / 'modal_damping.h5'}" in out and "damping.f1" in out
    with h5py.File(tmp_path / "modal_damping.h5", "r") as f:
        np.testing.assert_allclose(f["pads"][()], pads, rtol=1e-9, atol=1e-12 * abs(pads).max())
    # mbs with the first settings: the parts on disk belong to damping.f1 = 3
    assert run(["mbs", str(BASELINE), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "modal_damping.h5" in err[0] and "Traceback" not in err[0]
