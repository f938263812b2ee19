"""Defects 7 and 8 of issue 16: every user or environment error is one line with exit code
2 (no traceback); internal errors are one "please report" line naming a log; PETSc
option typos are reported; ``case.name`` cannot write outside ``results/``.
"""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest
from faults import BASELINE, COARSE, ENV, Result, cli, copy_results, serial_only

from railvib_hpc.cli import run

B = str(BASELINE)


def _expect_one_line(tally, fault: str, argv: list[str], capsys, needle: str) -> str:
    code = run([*map(str, argv)])
    cap = capsys.readouterr()
    lines = [ln for ln in cap.err.splitlines() if ln.strip()]
    clear = code == 2 and len(lines) == 1 and "Traceback" not in cap.err + cap.out
    tally.add(fault, "clear error" if clear else "silent wrong" if code == 0 else
              "traceback" if "Traceback" in cap.err else "unclear", cap.err.strip()[:300])
    assert clear, (code, cap.err)
    assert needle in lines[0], lines[0]
    return lines[0]


# ----------------------------------------------------------------------------- case files
def test_directory_as_case_file(tmp_path, capsys, tally):
    _expect_one_line(tally, "directory as case file", ["check", tmp_path], capsys,
                     "is a directory")


def test_empty_case_file_is_refused(tmp_path, capsys, tally):
    case = tmp_path / "empty.toml"
    case.write_text("# nothing set\n")
    _expect_one_line(tally, "empty case file", ["mesh", case, "--out", tmp_path / "o"],
                     capsys, "sets no key")
    assert not (tmp_path / "o" / "mesh.h5").exists()


def test_deeply_nested_toml(tmp_path, capsys, tally):
    case = tmp_path / "deep.toml"
    case.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n")
    _expect_one_line(tally, "deeply nested TOML", ["check", case], capsys, "case file")


def test_unreadable_case_file_in_process(tmp_path, capsys, tally, monkeypatch):
    case = tmp_path / "case.toml"
    case.write_text("[case]\nname = 'x'\n")

    def denied(self, *a, **k):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "read_text", denied)
    _expect_one_line(tally, "unreadable case file", ["check", case], capsys,
                     "cannot be read (Permission denied)")


def _as_nobody(folder: Path) -> tuple[list[str], object]:
    """The interpreter and ``preexec_fn`` that run the CLI as ``nobody`` from ``folder``.

    ``nobody`` may not enter the clone (a clone in a folder only root can enter, as
    ``mktemp -d`` makes one): the package is copied into ``folder`` (world-readable; ``-m``
    puts the working folder first on ``sys.path``) and the base interpreter is run
    (``/usr/bin/python3``, not the clone's ``.venv/bin/python``). The check of a case file
    imports the package and the system's numpy, scipy and mpi4py only."""
    import railvib_hpc

    shutil.copytree(Path(railvib_hpc.__file__).parent, folder / "railvib_hpc",
                    ignore=shutil.ignore_patterns("__pycache__"))
    for path in (folder, *folder.rglob("*")):
        os.chmod(path, 0o755 if path.is_dir() else 0o644)

    def preexec():
        os.setgid(65534)
        os.setuid(65534)

    return [os.path.realpath(sys.executable)], preexec


@serial_only
def test_unreadable_case_file_for_real(tally):
    """With a real permission error: as a normal user (chmod 000), or as root by dropping
    to ``nobody`` for the subprocess (which then runs a readable copy of the package:
    :func:`_as_nobody`)."""
    folder = Path(tempfile.mkdtemp(prefix="railvib-perm-"))
    try:
        os.chmod(folder, 0o755)
        case = folder / "case.toml"
        case.write_text("[case]\nname = 'x'\n")
        python, preexec, cwd = [sys.executable], None, None
        if os.geteuid() == 0:
            python, preexec = _as_nobody(folder)
            cwd = folder
        os.chmod(case, 0)
        env = {k: v for k, v in ENV.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
        t0 = time.perf_counter()
        try:
            p = subprocess.run([*python, "-m", "railvib_hpc", "check", str(case)],
                               capture_output=True, text=True, timeout=120, cwd=cwd,
                               env=env, preexec_fn=preexec)
        except PermissionError as exc:              # (the interpreter itself unreachable)
            pytest.skip(f"nobody cannot run {python[0]}: {exc}")
        res = tally.result("unreadable case file (real)",
                           Result(p.returncode, p.stdout, p.stderr,
                                  time.perf_counter() - t0, False))
        assert res.outcome == "clear error", res.err
        assert "cannot be read (Permission denied)" in res.error_lines[0]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


# ----------------------------------------------------------------------------- --out
def test_out_is_a_file(tmp_path, capsys, tally):
    f = tmp_path / "file"
    f.write_text("x")
    _expect_one_line(tally, "--out is a file", ["mesh", B, "--out", f, *COARSE], capsys,
                     f"cannot use the output folder {f}")


def test_out_below_a_file(tmp_path, capsys, tally):
    f = tmp_path / "file"
    f.write_text("x")
    _expect_one_line(tally, "--out below a file", ["mesh", B, "--out", f / "sub", *COARSE],
                     capsys, "Not a directory")


def test_out_name_too_long(tmp_path, capsys, tally):
    _expect_one_line(tally, "--out name too long", ["mesh", B, "--out", tmp_path / ("x" * 300),
                                                     *COARSE], capsys, "File name too long")


def test_out_on_a_read_only_file_system(tmp_path, capsys, tally, tmpfs):
    ro = tmpfs(1, ro=True)
    _expect_one_line(tally, "--out on a read-only mount", ["mesh", B, "--out", ro / "o",
                                                            *COARSE], capsys,
                     "Read-only file system")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only folders")
def test_out_in_a_read_only_folder(tmp_path, capsys, tally):
    ro = tmp_path / "ro"
    ro.mkdir()
    os.chmod(ro, stat.S_IRUSR | stat.S_IXUSR)
    try:
        _expect_one_line(tally, "--out in a read-only folder", ["mesh", B, "--out", ro / "o",
                                                                 *COARSE], capsys,
                         "Permission denied")
    finally:
        os.chmod(ro, 0o755)


# ----------------------------------------------------------------------------- case.name
@pytest.mark.parametrize("name, folder", [("../../escape", "escape"), ("/abs/name", "abs_name"),
                                          ("..", "case")])
def test_case_name_cannot_leave_results(name, folder, tmp_path, capsys, tally, monkeypatch):
    """The issue: case.name = '../../x' or an absolute name wrote outside results/."""
    case = tmp_path / "c.toml"
    case.write_text(f"[case]\nname = {name!r}\n")
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    monkeypatch.chdir(work)
    code = run(["mesh", str(case), *COARSE])
    out = capsys.readouterr().out
    inside = (work / "results" / folder / "mesh.h5").exists()
    outside = [p for p in tmp_path.rglob("mesh.h5") if work / "results" not in p.parents]
    tally.add(f"case.name {name!r}", "correct" if code == 0 and inside and not outside
              else "silent wrong")
    assert code == 0 and inside and not outside
    assert f"results go to results/{folder}" in out


# ----------------------------------------------------------------------------- model values
def test_empty_msh_file(tmp_path, capsys, tally):
    msh = tmp_path / "empty.msh"
    msh.write_text("")
    _expect_one_line(tally, "empty .msh", ["mesh", B, "--out", tmp_path / "o", "--set",
                                           f"mesh.file={str(msh)!r}"], capsys,
                     "holds no nodes")


def test_vehicle_start_beyond_the_track(work, capsys, tally):
    _expect_one_line(tally, "vehicle.x_start beyond the end", ["mbs", B, "--out", work,
                                                                *COARSE, "--set",
                                                                "vehicle.x_start=1000"],
                     capsys, "vehicle.x_start = 1000 m")


def test_max_basis_too_small(tmp_path, capsys, tally):
    _expect_one_line(tally, "modal.max_basis = 1", ["modal", B, "--out", tmp_path, *COARSE,
                                                     "--set", "modal.max_basis=1"], capsys,
                     "modal.max_basis = 1: must be 0 (automatic) or at least")


@pytest.mark.parametrize("setting, needle", [("vehicle.t_after=1e6", "vehicle.t_after = 1e+06"),
                                             ("mbs.dt=1e-9", "mbs.dt = 1e-09 s")])
def test_step_count_is_checked_before_allocating(work, setting, needle, capsys, tally):
    """The issue: t_after = 1e6 or mbs.dt = 1e-9 died with a 30 GB _ArrayMemoryError."""
    line = _expect_one_line(tally, f"{setting}", ["mbs", B, "--out", work, *COARSE, "--set",
                                                  setting], capsys, "steps")
    assert needle in line


def test_huge_mesh_is_refused_before_gmsh(tmp_path, capsys, tally):
    """The issue: mesh.layer_elements = 1e6 made gmsh raise a bare Exception."""
    _expect_one_line(tally, "mesh.layer_elements = 1e6", ["mesh", B, "--out", tmp_path,
                                                          *COARSE, "--set",
                                                          "mesh.layout=refined", "--set",
                                                          "mesh.layer_elements=1000000"],
                     capsys, "hexahedra")
    # the thesis layout (the default) has the APDL's own divisions: the key is refused
    _expect_one_line(tally, "mesh.layer_elements on the thesis layout",
                     ["mesh", B, "--out", tmp_path, *COARSE, "--set",
                      "mesh.layer_elements=1000000"], capsys, "applies to mesh.layout = 'refined'")


# ----------------------------------------------------------------------------- PETSc options
def test_stray_words_after_double_dash(tmp_path, capsys, tally):
    _expect_one_line(tally, "stray word after --", ["check", B, "--", "-railvib_eig_eps_tol",
                                                    "1e-9", "extra"],
                     capsys, "'extra' after '--' is neither a PETSc option")
    _expect_one_line(tally, "word without dash after --", ["check", B, "--", "eps_tol"],
                     capsys, "'eps_tol' after '--'")


def test_unused_petsc_option_is_reported(work, capsys, tally):
    code = run(["mbs", B, "--out", str(work), *COARSE, "--", "-railvib_eig_eps_tol", "1e-9"])
    err = capsys.readouterr().err
    ok = code == 0 and "nothing used: -railvib_eig_eps_tol" in err
    tally.add("PETSc option that nothing used", "warning" if ok else "silent wrong", err)
    assert ok, err


@pytest.mark.slow
@serial_only
def test_petsc_option_typo_and_bad_value_in_a_real_solve(prepared, tmp_path, tally):
    """A fresh modal solve (another mode count): the used option is not reported, the
    typo is; a bad value stops with one line."""
    out = copy_results(prepared, tmp_path / "o", ("mesh.h5", "mesh.msh", "mesh.xdmf",
                                                  "mesh_report.json"))
    sets = ["--set", "mesh.refinement=0.5", "--set", "modal.n_modes=6"]
    res = cli(["modal", B, "--out", out, *sets, "--", "-railvib_eig_st_ksp_type", "preonly",
               "-railvib_eig_st_ksp_tpye", "cg"], timeout=300)
    ok = res.code == 0 and "nothing used: -railvib_eig_st_ksp_tpye" in res.err \
        and "-railvib_eig_st_ksp_type " not in res.err.split("nothing used:")[-1]
    tally.add("PETSc option typo in a solve", "warning" if ok else res.outcome, res.err[-300:])
    assert ok, res.err
    (out / "modes.h5").unlink()
    res = tally.result("bad PETSc option value", cli(
        ["modal", B, "--out", out, *sets, "--", "-railvib_eig_st_ksp_type", "nosuchksp"],
        timeout=300))
    assert res.outcome == "clear error", res.err
    assert "check the options after '--'" in res.error_lines[0]
    assert not (out / "modes.h5").exists()


# ----------------------------------------------------------------------------- internal
def test_internal_error_is_one_line_with_a_log(work, capsys, monkeypatch, tally):
    from railvib_hpc.mbs import stage

    def bug(*a, **k):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(stage, "simulate_case", bug)
    code = run(["mbs", B, "--out", str(work), *COARSE])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    ok = code == 1 and len(lines) == 1 and "please report" in lines[0] \
        and "Traceback" not in err
    tally.add("internal error", "internal error" if ok else "unclear", err)
    assert ok, err
    log = Path(lines[0].split("the traceback is in ")[1])
    assert log.parent == work / ".railvib" and "ZeroDivisionError: a bug" in log.read_text()
    assert "Traceback" in log.read_text()


def test_no_exit_code_3_is_documented():
    import railvib_hpc.cli as cli_mod

    assert " 3 " not in cli_mod.__doc__ and "not implemented" not in cli_mod.__doc__

