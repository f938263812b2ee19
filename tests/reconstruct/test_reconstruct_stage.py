"""The reconstruct stage: mbs.h5 in, fields/stress/probes out; validation and reuse."""

from __future__ import annotations

import io

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from reconstruct_cases import (
    histories,
    read_modes,
    relative_error,
    superpose,
    write_mbs,
    write_static_basis,
)
from test_reconstruct_fields import check_xdmf

from railvib_hpc.errors import UserError
from railvib_hpc.log import Reporter
from railvib_hpc.reconstruct import ReconstructInputError, reconstruct_outputs
from railvib_hpc.reconstruct import fields as fields_mod

comm = MPI.COMM_WORLD
M, K, NT = 5, 2, 60


def _inputs(folder, coarse_modes, **mbs_kw):
    """mbs.h5 (random histories of the first M modes + a static correction of K shapes)."""
    t, q, qd, qdd = histories(NT, M, seed=21)
    rng = np.random.default_rng(22)
    g = [rng.standard_normal((NT, K)) * s for s in (1e-5, 1e-3, 1e-1)]
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "sim").mkdir(exist_ok=True)
        with h5py.File(coarse_modes, "r") as f:
            n = f["mesh/points"].shape[0]
        write_static_basis(folder / "static.h5", n, K)
        write_mbs(folder / "sim" / "mbs.h5", t, q, qd, qdd,
                  static={"basis_file": "../static.h5", "basis": "basis", "g": g[0],
                          "g_dot": g[1], "g_ddot": g[2]}, **mbs_kw)
    comm.Barrier()
    return folder / "sim" / "mbs.h5", (t, q, qd, qdd, g)


def _run(coarse_modes, mbs, out, stream=None, **kw):
    rep = Reporter(comm.rank, stream or io.StringIO())
    return reconstruct_outputs(coarse_modes, mbs, out, comm, rep, **kw), rep


@pytest.mark.mpi
def test_stage_outputs_equal_serial_superposition(coarse_modes, shared_tmp):
    mbs, (t, q, qd, qdd, g) = _inputs(shared_tmp, coarse_modes)
    out = shared_tmp / "res"
    window = (t[5], t[50])
    res, rep = _run(coarse_modes, mbs, out, stride=4, window=window,
                    stress_times=[t[9], t[29]], user_probes={"p1": (14.0, -9.0, 4.0)},
                    correction_rates=True)
    comm.Barrier()
    steps = np.arange(5, 51, 4)
    phi, mesh = read_modes(coarse_modes, M)
    with h5py.File(shared_tmp / "static.h5", "r") as f:
        basis = f["basis"][()]
    with h5py.File(out / "fields.h5", "r") as f:
        assert int(f.attrs["complete"]) == 1 and len(f.attrs["inputs_sha256"]) == 64
        assert np.array_equal(f["steps"][()], steps) and np.array_equal(f["time"][()], t[steps])
        for name, h, gi in (("displacement", q, g[0]), ("velocity", qd, g[1]),
                            ("acceleration", qdd, g[2])):
            ref = superpose(phi, h[steps]) + superpose(basis, gi[steps])
            assert relative_error(f["fields/" + name][()], ref) < 1e-12
        assert f["stress/von_mises"].shape == (2, len(mesh["hexes"]))
        assert np.allclose(f["stress/time"][()], [t[9], t[29]])
    check_xdmf(out / "fields.xdmf", out / "fields.h5")
    check_xdmf(out / "stress.xdmf", out / "fields.h5")
    with h5py.File(out / "probes.h5", "r") as f:
        names = [n.decode() for n in f["names"][()]]
        assert names[-1] == "p1" and len(names) == 15  # 14 mesh probes + p1
        assert f["probes/p1/displacement"].shape == (46, 3)      # window, full resolution
        assert np.array_equal(f["probes/p1/time"][()], t[5:51])
        x = f["rail/x"][()]
        assert f["rail/bending_moment"].shape == (46, 2, x.shape[1])
        assert f["rail/bending_moment_ends"].shape == (46, 2, x.shape[1] - 1, 2)
    assert sorted(p.name for p in (out / "probes").iterdir()) == sorted(n + ".csv"
                                                                       for n in names)
    assert res["reused"] == {"fields": False, "stress": False, "probes": False}
    assert res["fields"]["n_steps"] == len(steps) and res["fields"]["n_extra"] == K
    assert res["gemm_gflops"] > 0 and res["write_gb_per_s"] > 0
    assert res["bytes_written"] == 3 * len(steps) * phi.shape[1] * 3 * 8
    assert {"fields", "stress", "probes", "total"} <= set(res["seconds"])
    # the stresses are computed inside the fields stage (into the temporary file)
    assert [n for n, _ in rep.timings] == ["reconstruct fields", "reconstruct probes"]
    assert res["stress"]["n_times"] == 2


@pytest.mark.mpi
def test_static_correction_rates_off_is_the_mode_acceleration_method(coarse_modes, shared_tmp):
    """Default: the static correction enters the displacements only; velocities and
    accelerations are the modes' own (``Phi q_dot``, ``Phi q_ddot``)."""
    mbs, (_, q, qd, qdd, g) = _inputs(shared_tmp, coarse_modes)
    out = shared_tmp / "mam"
    _run(coarse_modes, mbs, out, stride=3)
    comm.Barrier()
    steps = np.arange(0, NT, 3)
    phi, _ = read_modes(coarse_modes, M)
    with h5py.File(shared_tmp / "static.h5", "r") as f:
        basis = f["basis"][()]
    with h5py.File(out / "fields.h5", "r") as f:
        ref = superpose(phi, q[steps]) + superpose(basis, g[0][steps])
        assert relative_error(f["fields/displacement"][()], ref) < 1e-12
        for name, h in (("velocity", qd), ("acceleration", qdd)):
            assert relative_error(f["fields/" + name][()], superpose(phi, h[steps])) < 1e-12
    # the probes follow the same rule: with the rates the accelerations change, the
    # displacements do not
    _run(coarse_modes, mbs, shared_tmp / "rates", stride=3, correction_rates=True)
    comm.Barrier()
    with h5py.File(out / "probes.h5", "r") as f, \
            h5py.File(shared_tmp / "rates" / "probes.h5", "r") as r:
        for name in ("slab1", "footing"):
            d, dr = f[f"probes/{name}/displacement"][()], r[f"probes/{name}/displacement"][()]
            a, ar = f[f"probes/{name}/acceleration"][()], r[f"probes/{name}/acceleration"][()]
            assert relative_error(d, dr) < 1e-12
            assert relative_error(a, ar) > 1e-3
    comm.Barrier()


@pytest.mark.mpi
def test_rerun_reuses_and_option_changes_recompute(coarse_modes, shared_tmp):
    mbs, (t, *_) = _inputs(shared_tmp, coarse_modes)
    out = shared_tmp / "res"
    kw = {"stride": 3, "stress_times": [t[10]], "user_probes": [(14.0, -9.0, 4.0)]}
    _run(coarse_modes, mbs, out, **kw)
    comm.Barrier()
    stamp = {p: (out / p).stat().st_mtime_ns for p in ("fields.h5", "probes.h5")}
    stream = io.StringIO()
    res, _ = _run(coarse_modes, mbs, out, stream=stream, **kw)
    assert res["reused"] == {"fields": True, "stress": True, "probes": True}
    if comm.rank == 0:
        text = stream.getvalue()
        assert "reusing" in text and f"reusing {out / 'probes.h5'}" in text
    comm.Barrier()
    assert {p: (out / p).stat().st_mtime_ns for p in stamp} == stamp
    # XDMF files of the earlier form (no views) are rewritten; the data are reused
    if comm.rank == 0:
        for name in ("fields", "stress"):
            (out / f"{name}_views.h5").unlink()
    comm.Barrier()
    stream = io.StringIO()
    res, _ = _run(coarse_modes, mbs, out, stream=stream, **kw)
    assert res["reused"] == {"fields": True, "stress": True, "probes": True}
    if comm.rank == 0:
        text = stream.getvalue()
        assert f"rewrote {out / 'fields.xdmf'}" in text
        assert f"rewrote {out / 'stress.xdmf'}" in text
    comm.Barrier()
    assert {p: (out / p).stat().st_mtime_ns for p in stamp} == stamp
    check_xdmf(out / "fields.xdmf", out / "fields.h5")
    check_xdmf(out / "stress.xdmf", out / "fields.h5")
    # other probes: only the probes are recomputed
    res, _ = _run(coarse_modes, mbs, out, **{**kw, "user_probes": [(15.0, -9.0, 4.0)]})
    assert res["reused"] == {"fields": True, "stress": True, "probes": False}
    # other stress times: the stresses only
    res, _ = _run(coarse_modes, mbs, out, **{**kw, "stress_times": [t[20]]})
    assert res["reused"] == {"fields": True, "stress": False, "probes": False}
    # float32: new fields (and stresses of them)
    res, _ = _run(coarse_modes, mbs, out, float32=True, **kw)
    assert res["reused"]["fields"] is False and res["fields"]["float32"] is True
    comm.Barrier()
    with h5py.File(out / "fields.h5", "r") as f:
        assert f["fields/displacement"].dtype == np.float32
        assert int(f.attrs["stress_complete"]) == 1
    check_xdmf(out / "fields.xdmf", out / "fields.h5")          # float32 views
    # a new multibody result (other digest) recomputes everything
    mbs, _ = _inputs(shared_tmp, coarse_modes, digest="mbs-2")
    res, _ = _run(coarse_modes, mbs, out, float32=True, **kw)
    assert res["reused"] == {"fields": False, "stress": False, "probes": False}


@pytest.mark.mpi
def test_failed_stage_leaves_no_fields_file(coarse_modes, shared_tmp, monkeypatch):
    mbs, _ = _inputs(shared_tmp, coarse_modes)
    out = shared_tmp / "res"

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(fields_mod, "write_slab", broken)
    monkeypatch.setattr(fields_mod, "_gather_write", broken)
    with pytest.raises((OSError, RuntimeError), match="disk full"):
        _run(coarse_modes, mbs, out)
    comm.Barrier()
    assert sorted(p.name for p in out.iterdir() if p.name != ".railvib") == []
    monkeypatch.undo()
    res, _ = _run(coarse_modes, mbs, out)                   # and a rerun works
    assert res["reused"]["fields"] is False and (out / "fields.h5").is_file()


@pytest.mark.mpi
def test_stress_failure_leaves_no_fields_file(coarse_modes, shared_tmp, monkeypatch):
    """Fields and stresses are one atomic result: a failing stress pass leaves nothing."""
    from railvib_hpc.reconstruct import stress as stress_mod

    mbs, (t, *_) = _inputs(shared_tmp, coarse_modes)
    out = shared_tmp / "res"

    def broken(*args, **kwargs):
        raise FloatingPointError("bad stress")

    monkeypatch.setattr(stress_mod, "element_stress", broken)
    with pytest.raises((FloatingPointError, RuntimeError), match="bad stress"):
        _run(coarse_modes, mbs, out, stress_times=[t[3]])
    comm.Barrier()
    assert sorted(p.name for p in out.iterdir() if p.name != ".railvib") == []


def _bad_inputs(folder, coarse_modes, kind):
    t, q, qd, qdd = histories(NT, M)
    mbs = folder / "mbs.h5"
    if comm.rank == 0:
        folder.mkdir(parents=True, exist_ok=True)
        static = None
        if kind == "too_many_modes":
            t, q, qd, qdd = histories(NT, 9)
        elif kind == "shape":
            qd = qd[:, :3]
        elif kind == "nt":
            qdd = qdd[:-1]
        elif kind in ("static_missing", "static_shape"):
            if kind == "static_shape":
                write_static_basis(folder / "static.h5", 17, 2)
            static = {"basis_file": "static.h5", "basis": "basis",
                      **{k: np.zeros((NT, 2)) for k in ("g", "g_dot", "g_ddot")}}
        elif kind == "time":
            t = t[::-1]
        write_mbs(mbs, t, q, qd, qdd, static=static, complete=0 if kind == "incomplete" else 1)
    comm.Barrier()
    return mbs


@pytest.mark.mpi
@pytest.mark.parametrize("kind, message", [
    ("too_many_modes", r"mbs.h5: modal/q has 9 modal coordinates but .*modes.h5 holds 8"),
    ("shape", r"mbs.h5: modal/q, modal/q_dot, modal/q_ddot have different shapes"),
    ("nt", r"mbs.h5: dataset 'modal/q_ddot' has shape \(59, 5\), expected \(nt, columns\) "
           r"with nt = 60"),
    ("incomplete", r"mbs.h5 is incomplete"),
    ("static_missing", r"static-correction basis file .*static.h5 not found"),
    ("static_shape", r"static.h5: dataset 'basis' has shape \(2, 17, 3\), expected"),
    ("time", r"'time' must be finite and strictly increasing"),
])
def test_invalid_inputs_raise_on_every_rank(coarse_modes, shared_tmp, kind, message):
    mbs = _bad_inputs(shared_tmp, coarse_modes, kind)
    with pytest.raises(ReconstructInputError, match=message):
        _run(coarse_modes, mbs, shared_tmp / "res")
    assert not (shared_tmp / "res" / "fields.h5").exists()


@pytest.mark.mpi
def test_invalid_options_and_missing_files(coarse_modes, shared_tmp):
    mbs, (t, *_) = _inputs(shared_tmp, coarse_modes)
    out = shared_tmp / "res"
    with pytest.raises(UserError, match="not found"):
        _run(coarse_modes, shared_tmp / "nope.h5", out)
    with pytest.raises(UserError, match="contains no step"):
        _run(coarse_modes, mbs, out, window=(t[-1] + 1, t[-1] + 2))
    with pytest.raises(UserError, match="stride must be a positive integer"):
        _run(coarse_modes, mbs, out, stride=0)
    with pytest.raises(UserError, match="outside the stored time range"):
        _run(coarse_modes, mbs, out, stride=2, stress_times=[t[-1] + 0.5])
    with pytest.raises(UserError, match="three finite numbers"):
        _run(coarse_modes, mbs, out, user_probes=[(1.0, 2.0)])
    with pytest.raises(UserError, match="outside the hexahedral mesh"):
        _run(coarse_modes, mbs, out, user_probes=[(1e3, 0.0, 0.0)])
