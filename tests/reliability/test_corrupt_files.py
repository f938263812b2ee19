"""Defect 5 of issue 16: NaN, garbage and truncated stage files never become a "complete"
report.

Each stage file is corrupted four ways: a NaN written into it after it was recorded
(``nan``: its content digest changes), the same with its record deleted so that only
the data checks can find it (``nan-unrecorded``), raw bytes over a dataset
(``garbage``) and half of the file cut off (``truncated``). A command that reads the
file refuses naming it; the command that writes it (and ``run``) recomputes it, with
the same numbers as before.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import h5py
import numpy as np
import pytest
from faults import BASELINE, COARSE, copy_results

from railvib_hpc.cli import run

B = str(BASELINE)
KINDS = ("nan", "nan-unrecorded", "garbage", "truncated")
#: file -> (dataset to corrupt, a command that reads the file, its extra case settings)
READERS = {
    "modes.h5": ("modes/translation", "mbs", []),
    "static.h5": ("static/translation", "mbs", ["--set", "mbs.static_correction=true"]),
    "mbs.h5": ("modal/q", "reconstruct", []),
    "fields.h5": ("fields/acceleration", "assess", []),
    "probes.h5": ("probes/slab1/acceleration", "assess", []),
}


def record_path(path: Path) -> Path:
    """Where the stage-file layer keeps the record of ``path``."""
    return path.parent / ".railvib" / f"{path.name}.json"


def inject(path: Path, kind: str, dataset: str) -> None:
    """Corrupt ``path`` (see the module notes)."""
    if kind in ("nan", "nan-unrecorded"):
        with h5py.File(path, "r+") as f:
            d = f[dataset]
            idx = tuple(s // 2 for s in d.shape)
            d[idx] = np.nan
        if kind == "nan-unrecorded":
            record_path(path).unlink(missing_ok=True)
    elif kind == "garbage":
        with h5py.File(path, "r") as f:
            d = f[dataset]
            offset, nbytes = d.id.get_offset(), d.id.get_storage_size()
        rng = np.random.default_rng(16)
        with open(path, "r+b") as fh:
            fh.seek(offset + nbytes // 2)
            fh.write(rng.bytes(min(4096, nbytes // 2)))
    elif kind == "truncated":
        os.truncate(path, path.stat().st_size // 2)
    else:  # pragma: no cover
        raise ValueError(kind)


def _one_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _record(tally, fault: str, code: int, err: str) -> None:
    clear = code == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    tally.add(fault, "clear error" if clear else "silent wrong" if code == 0 else "unclear",
              err.strip())


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("name", list(READERS))
def test_reader_refuses_a_corrupt_input(name, kind, prepared, prepared_static, tmp_path,
                                        capsys, tally):
    dataset, command, sets = READERS[name]
    src = prepared_static if name == "static.h5" else prepared
    out = copy_results(src, tmp_path / "o")
    if name == "static.h5":
        copy_results(prepared_static, out, ("static.h5", "mbs.h5"))
    inject(out / name, kind, dataset)
    code = run([command, B, "--out", str(out), *COARSE, *sets])
    err = capsys.readouterr().err
    _record(tally, f"{kind} {name} read by {command}", code, err)
    assert code == 2, err
    line = _one_line(err)
    assert f"{out / name} " in line and ("is corrupt" in line or "cannot be read" in line)
    expected = {"nan": "its content changed after it was written",
                "nan-unrecorded": "non-finite value",
                "garbage": "its content changed after it was written"}.get(kind, "")
    assert expected in line
    assert "run 'railvib" in line


@pytest.mark.parametrize("kind", KINDS)
def test_garbled_mesh_is_rebuilt(kind, prepared, tmp_path, capsys, tally):
    """The issue: a mesh.h5 garbled in the middle was reused, then every rerun failed with
    IndexError until it was deleted by hand."""
    out = copy_results(prepared, tmp_path / "o", ("mesh.h5", "mesh.msh", "mesh.xdmf",
                                                  "mesh_report.json"))
    inject(out / "mesh.h5", kind, "mesh/points" if kind.startswith("nan") else "mesh/hexes")
    code = run(["mesh", B, "--out", str(out), *COARSE])
    text = capsys.readouterr().out
    ok = code == 0 and f"recomputing {out / 'mesh.h5'}: it " in text
    with h5py.File(out / "mesh.h5", "r") as f, h5py.File(prepared / "mesh.h5", "r") as g:
        same = all(np.array_equal(f[k][()], g[k][()]) for k in ("mesh/points", "mesh/hexes"))
    tally.add(f"{kind} mesh.h5 rebuilt by mesh", "recomputed" if ok and same else
              "silent wrong", text.splitlines()[0] if text else "")
    assert ok and same, text


def test_garbage_hexes_without_record_are_found_by_the_data_check(prepared, tmp_path):
    from railvib_hpc.io.formats.mesh import check_mesh

    out = copy_results(prepared, tmp_path / "o", ("mesh.h5",))
    inject(out / "mesh.h5", "garbage", "mesh/hexes")
    assert check_mesh(out / "mesh.h5")


@pytest.mark.slow
def test_owner_recomputes_corrupt_modes_with_identical_numbers(prepared, tmp_path, capsys,
                                                               tally):
    out = copy_results(prepared, tmp_path / "o")
    inject(out / "modes.h5", "nan-unrecorded", "modes/translation")
    code = run(["modal", B, "--out", str(out), *COARSE])
    text = capsys.readouterr().out
    with h5py.File(out / "modes.h5", "r") as f, h5py.File(prepared / "modes.h5", "r") as g:
        same = np.array_equal(f["modes/translation"][()], g["modes/translation"][()])
    ok = code == 0 and "recomputing" in text and "non-finite" in text and same
    tally.add("nan modes.h5 recomputed by modal", "recomputed" if ok else "silent wrong")
    assert ok, text


def test_owner_recomputes_corrupt_static_solutions(prepared_static, tmp_path, capsys, tally):
    out = copy_results(prepared_static, tmp_path / "o", ("mesh.h5", "mesh.msh", "mesh.xdmf",
                                                         "mesh_report.json", "modes.h5",
                                                         "modes.xdmf", "static.h5"))
    inject(out / "static.h5", "garbage", "static/translation")
    code = run(["modal", B, "--out", str(out), *COARSE, "--set", "mbs.static_correction=true"])
    text = capsys.readouterr().out
    with h5py.File(out / "static.h5", "r") as f, \
            h5py.File(prepared_static / "static.h5", "r") as g:
        same = np.array_equal(f["static/translation"][()], g["static/translation"][()])
    ok = code == 0 and f"recomputing {out / 'static.h5'}: it is corrupt" in text and same
    tally.add("garbage static.h5 recomputed by modal", "recomputed" if ok else "silent wrong")
    assert ok, text


@pytest.mark.parametrize("name, kind", [("fields.h5", "garbage"), ("probes.h5", "truncated"),
                                        ("fields.h5", "nan-unrecorded")])
def test_reconstruct_recomputes_its_corrupt_outputs(name, kind, prepared, tmp_path, capsys,
                                                    tally):
    out = copy_results(prepared, tmp_path / "o")
    inject(out / name, kind, READERS[name][0])
    code = run(["reconstruct", B, "--out", str(out), *COARSE])
    text = capsys.readouterr().out
    ds = READERS[name][0]
    with h5py.File(out / name, "r") as f, h5py.File(prepared / name, "r") as g:
        same = np.array_equal(f[ds][()], g[ds][()])
    ok = code == 0 and f"recomputing {out / name}:" in text and same
    tally.add(f"{kind} {name} recomputed by reconstruct", "recomputed" if ok else
              "silent wrong")
    assert ok, text


@pytest.mark.slow
def test_huge_modal_coordinate_never_reaches_a_report(prepared, tmp_path, capsys, tally):
    """The issue: mbs.h5 with modal/q[400] = 1e300 gave exit 0, "no limit exceeded" and a
    building displacement of 1e298 m. Without its record only the plausibility bound can
    find it; run recomputes mbs.h5 and the report has the original numbers."""
    out = copy_results(prepared, tmp_path / "o")
    with h5py.File(out / "mbs.h5", "r+") as f:
        f["modal/q"][400, 0] = 1e300
    record_path(out / "mbs.h5").unlink(missing_ok=True)
    code = run(["reconstruct", B, "--out", str(out), *COARSE])
    err = capsys.readouterr().err
    _record(tally, "1e300 in mbs.h5 read by reconstruct", code, err)
    assert code == 2 and "above the bound" in _one_line(err)
    code = run(["run", B, "--out", str(out), *COARSE])
    text = capsys.readouterr().out
    assert code == 0 and f"recomputing {out / 'mbs.h5'}: it is corrupt (modal/q reaches " \
        "1e+300, above the bound" in text
    a = json.loads((out / "assessment.json").read_text())["thesis_comparison"]
    b = json.loads((prepared / "assessment.json").read_text())["thesis_comparison"]
    same = all(a[k]["railvib"] == b[k]["railvib"] for k in b)
    tally.add("1e300 in mbs.h5 recomputed by run", "recomputed" if same else "silent wrong")
    assert same


def test_nan_mbs_is_not_reused_by_every_later_run(prepared, tmp_path, capsys, tally):
    """The issue: an mbs.h5 with NaNs was reused by every later run, which failed each time."""
    out = copy_results(prepared, tmp_path / "o")
    inject(out / "mbs.h5", "nan", "modal/q_ddot")
    code = run(["mbs", B, "--out", str(out), *COARSE])
    text = capsys.readouterr().out
    with h5py.File(out / "mbs.h5", "r") as f, h5py.File(prepared / "mbs.h5", "r") as g:
        same = np.array_equal(f["modal/q_ddot"][()], g["modal/q_ddot"][()])
    ok = code == 0 and "recomputing" in text and same
    tally.add("nan mbs.h5 recomputed by mbs", "recomputed" if ok else "silent wrong")
    assert ok, text


def test_nan_in_the_modes_never_makes_a_complete_fields_file(prepared, tmp_path, monkeypatch,
                                                             capsys, tally):
    """The issue: NaN in modes/translation gave fields.h5 with NaNs and complete = 1.
    Even when the NaN slips past the input checks (here: they are switched off), the
    write-time check of every block stops before a fields.h5 exists."""
    from railvib_hpc.io.stage_protocol import StageContext

    out = copy_results(prepared, tmp_path / "o", ("modes.h5", "mbs.h5"))
    inject(out / "modes.h5", "nan-unrecorded", "modes/translation")
    monkeypatch.setattr(StageContext, "require", lambda self, *a, **k: {})
    code = run(["reconstruct", B, "--out", str(out), *COARSE])
    err = capsys.readouterr().err
    _record(tally, "nan modes.h5 past the input checks", code, err)
    assert code == 2 and "non-finite" in _one_line(err)
    assert not (out / "fields.h5").exists()
    assert not [p for p in out.iterdir() if ".part-" in p.name]
