"""ParaView opens every XDMF output of a real run with all its data (issue 16, defect 9).

The coarse model's stages ``mesh``, ``modal``, ``mbs``, ``reconstruct`` (``railvib run``
without ``assess``) write ``mesh.xdmf``, ``modes.xdmf``, ``fields.xdmf`` and
``stress.xdmf``; ``pvbatch`` (``tests/io/paraview_probe.py``) opens each with the legacy
"XDMF Reader" and with ``Xdmf3ReaderS``/``Xdmf3ReaderT`` (ParaView 5.11's default for
XDMF 3 files) and reports, at every time step, the blocks, the arrays, their ranges and
sample tuples. Everything is compared with the HDF5 datasets themselves.

ParaView is a test dependency: ``make test`` installs Debian's ``python3-paraview``. A
missing ``pvbatch`` fails this test; users without ParaView may set
``RAILVIB_SKIP_PARAVIEW=1`` to skip it (CI never sets it).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import time
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np
import pytest
from mpi4py import MPI

from railvib_hpc.cli import run

ROOT = Path(__file__).resolve().parents[2]
BASELINE = ROOT / "jobs" / "thesis_baseline.toml"
PROBE = Path(__file__).with_name("paraview_probe.py")
COARSE = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=20",
          "--set", "output.dt=0.01"]
#: Opt-out for users without ParaView (never set in CI).
SKIP_ENV = "RAILVIB_SKIP_PARAVIEW"
READERS = ("XDMFReader", "Xdmf3ReaderS", "Xdmf3ReaderT")
OUTPUTS = ("mesh", "modes", "fields", "stress")


@pytest.fixture(scope="module")
def pvbatch() -> str:
    if MPI.COMM_WORLD.size > 1:
        pytest.skip("serial test (runs in the serial pass of make test)")
    if os.environ.get(SKIP_ENV, "") not in ("", "0"):
        pytest.skip(f"{SKIP_ENV} is set: ParaView checks skipped on request")
    exe = shutil.which("pvbatch")
    if exe is None:
        pytest.fail(f"pvbatch (ParaView) not found on PATH: install it (Debian/Ubuntu: "
                    f"apt-get install python3-paraview, done by `make test`; conda: "
                    f"paraview) or set {SKIP_ENV}=1 to skip the ParaView checks",
                    pytrace=False)
    return exe


@pytest.fixture(scope="module")
def loaded(pvbatch, tmp_path_factory):
    """Run the coarse model (the stages that write XDMF), then let pvbatch open every XDMF
    output."""
    out = tmp_path_factory.mktemp("paraview") / "run"
    t0 = time.perf_counter()
    for stage in ("mesh", "modal", "mbs", "reconstruct"):     # `run` without `assess`
        assert run([stage, str(BASELINE), *COARSE, "--out", str(out)]) == 0
    t_run = time.perf_counter() - t0
    report = out / "paraview.json"
    env = _pvbatch_env()
    t0 = time.perf_counter()
    proc = subprocess.run([pvbatch, str(PROBE), str(report),
                           *(str(out / f"{name}.xdmf") for name in OUTPUTS)],
                          env=env, cwd=out.parent, capture_output=True, text=True, timeout=900)
    t_pv = time.perf_counter() - t0
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "Skipping unrecognized array type" not in proc.stderr, proc.stderr[-3000:]
    assert "ERR|" not in proc.stderr and "XDMF Error" not in proc.stderr, proc.stderr[-3000:]
    print(f"\ncoarse run {t_run:.1f} s, pvbatch {t_pv:.1f} s")
    return out, json.loads(report.read_text())


def _pvbatch_env() -> dict[str, str]:
    """ParaView's own Python: none of the project's (or an MPI launcher's) environment."""
    return {k: v for k, v in os.environ.items()
            if not k.startswith(("PMIX_", "PMI_", "PYTHON", "VIRTUAL_ENV"))
            and not (k.startswith("OMPI_") and not k.startswith("OMPI_ALLOW_RUN_AS_ROOT"))}


def _fields(path: Path) -> tuple[np.ndarray, dict, int, int, np.ndarray]:
    """Times, the three nodal fields, node and element counts and parts of fields.h5."""
    with h5py.File(path, "r") as f:
        return (f["time"][()], {name: f[f"fields/{name}"][()]
                                for name in ("displacement", "velocity", "acceleration")},
                len(f["mesh/points"]), len(f["mesh/hexes"]), f["mesh/hex_part"][()])


def _check_arrays(got: dict, expected: dict, where: str) -> None:
    """``got``: ParaView's arrays; ``expected``: name -> (n, components) array from HDF5."""
    assert set(got) == set(expected), f"{where}: ParaView arrays {sorted(got)}"
    for name, ref in expected.items():
        ref = ref.reshape(len(ref), -1).astype(float)
        a = got[name]
        assert a["n_tuples"] == len(ref) and a["n_components"] == ref.shape[1], (where, name)
        np.testing.assert_array_equal(np.array(a["range"]),
                                      np.stack([ref.min(axis=0), ref.max(axis=0)], axis=1),
                                      err_msg=f"{where}: range of {name}")
        for j, values in a["samples"].items():
            np.testing.assert_array_equal(values, ref[int(j)],
                                          err_msg=f"{where}: {name}[{j}]")


def _check_series(files: dict, times: np.ndarray, n: int, ne: int, part: np.ndarray,
                  point: Callable[[int], dict], cell: Callable[[int], dict],
                  label: str) -> None:
    for reader in READERS:
        res = files[reader]
        np.testing.assert_array_equal(res["times"], times, err_msg=f"{label} {reader}: times")
        assert len(res["steps"]) == len(times)
        for k, step in enumerate(res["steps"]):
            where = f"{label} {reader} step {k}"
            assert list(step["blocks"]) == ["0"], where
            b = step["blocks"]["0"]
            assert (b["n_points"], b["n_cells"]) == (n, ne), where
            _check_arrays(b["point"], point(k), where)
            _check_arrays(b["cell"], {"part_id": part, **cell(k)}, where)


def test_paraview_chooses_an_xdmf3_reader_by_default(loaded):
    out, report = loaded
    for name in OUTPUTS:
        # the XML name of the legacy "XDMF Reader" is XdmfReader
        assert report["files"][str(out / f"{name}.xdmf")]["default"] in (
            "XdmfReader", "Xdmf3ReaderS", "Xdmf3ReaderT")


def test_mesh_xdmf_in_every_reader(loaded):
    out, report = loaded
    files = report["files"][str(out / "mesh.xdmf")]
    with h5py.File(out / "mesh.h5", "r") as f:
        n = f["mesh/points"].shape[0]
        blocks = [(len(f["mesh/hexes"]), f["mesh/hex_part"][()]),
                  (len(f["mesh/lines"]), f["mesh/line_part"][()])]
    for reader in READERS:
        res = files[reader]
        assert res["times"] == [] and len(res["steps"]) == 1
        got = list(res["steps"][0]["blocks"].values())
        assert len(got) == 2, reader
        for b, (ne, part) in zip(got, blocks):
            assert (b["n_points"], b["n_cells"]) == (n, ne), reader
            _check_arrays(b["point"], {}, f"mesh {reader}")
            _check_arrays(b["cell"], {"part_id": part}, f"mesh {reader}")


def test_modes_xdmf_in_every_reader(loaded):
    out, report = loaded
    with h5py.File(out / "modes.h5", "r") as f:
        phi = f["modes/translation"][()]
        n, ne, part = len(f["mesh/points"]), len(f["mesh/hexes"]), f["mesh/hex_part"][()]
    assert len(phi) == 20
    _check_series(report["files"][str(out / "modes.xdmf")], np.arange(1.0, 21.0), n, ne, part,
                  lambda k: {"mode_shape": phi[k]}, lambda k: {}, "modes")


def test_fields_xdmf_in_every_reader(loaded):
    out, report = loaded
    t, data, n, ne, part = _fields(out / "fields.h5")
    assert len(t) > 50 and np.abs(data["acceleration"]).max() > 0
    _check_series(report["files"][str(out / "fields.xdmf")], t, n, ne, part,
                  lambda k: {name: a[k] for name, a in data.items()}, lambda k: {}, "fields")


def test_stress_xdmf_in_every_reader(loaded):
    out, report = loaded
    with h5py.File(out / "fields.h5", "r") as f:
        t = f["stress/time"][()]
        data = {name: f[f"stress/{name}"][()] for name in ("von_mises", "strain_eq")}
        n, ne, part = len(f["mesh/points"]), len(f["mesh/hexes"]), f["mesh/hex_part"][()]
    assert len(t) == 2 and data["von_mises"].max() > 0
    _check_series(report["files"][str(out / "stress.xdmf")], t, n, ne, part,
                  lambda k: {}, lambda k: {name: a[k] for name, a in data.items()}, "stress")


#: The bare soil under a moving load (``track.count = 0``, ``[load]``; the case of
#: tests/transient/test_surface_load_case.py): the transient stage's fields of a mesh
#: without a track.
BARE_SOIL = ["mesh.refinement=0.25", "track.count=0", "load.force=1e5", "load.speed=50",
             "load.x_start=3", "load.x_end=4.5", "load.ramp_time=0.01",
             "modal.lumped_mass=true", "transient.engine=explicit", "output.dt=0.002",
             "transient.checkpoint_interval=0", "output.stress_times=[]",
             "transient.f_max=100"]


def test_the_bare_soils_transient_fields_in_every_reader(pvbatch, tmp_path):
    """The fields and mesh of a case without a track open in every reader with the arrays
    of fields.h5 (no rail, no track part)."""
    from railvib_hpc.config import load_case
    from railvib_hpc.log import Reporter
    from railvib_hpc.transient.stage import run_transient_stage

    out = tmp_path / "bare"
    run_transient_stage(load_case(BASELINE, BARE_SOIL), out, MPI.COMM_SELF, Reporter(0))
    report = tmp_path / "paraview.json"
    env = _pvbatch_env()
    proc = subprocess.run([pvbatch, str(PROBE), str(report), str(out / "fields.xdmf")],
                          env=env, cwd=tmp_path, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert "ERR|" not in proc.stderr and "XDMF Error" not in proc.stderr, proc.stderr[-3000:]
    t, data, n, ne, part = _fields(out / "fields.h5")
    assert len(t) > 5 and np.abs(data["velocity"]).max() > 0
    _check_series(json.loads(report.read_text())["files"][str(out / "fields.xdmf")], t, n, ne,
                  part, lambda k: {name: a[k] for name, a in data.items()}, lambda k: {},
                  "bare-soil fields")
