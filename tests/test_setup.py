"""tools/setup.sh with a bring-your-own stack: apt disabled, nothing installed system-wide.

The "own stack" here is the installed Debian one, presented as a cluster or conda user
would: PETSC_DIR/SLEPC_DIR exported, or no dpkg on PATH. ``dpkg``, ``dpkg-query``,
``apt-get``, ``apt`` and ``sudo`` are replaced by stubs that record any call and fail.
"""

from __future__ import annotations

import glob
import os
import subprocess
import sysconfig
from pathlib import Path

import pytest
from mpi4py import MPI

ROOT = Path(__file__).resolve().parents[1]
SETUP = ROOT / "tools" / "setup.sh"
SYSTEM_PYTHON = "/usr/bin/python3"
BLOCKED = ("dpkg", "dpkg-query", "apt-get", "apt", "sudo")

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial test")


def _debian_dirs() -> tuple[str, str]:
    petsc = sorted(glob.glob("/usr/lib/petscdir/petsc3.*/*-real"))
    slepc = sorted(glob.glob("/usr/lib/slepcdir/slepc3.*/*-real"))
    assert petsc and slepc, "the Debian PETSc/SLEPc stack (make setup) is not installed"
    return petsc[0], slepc[0]


def _stubs(folder: Path) -> Path:
    """Failing, recording stand-ins for the package tools."""
    folder.mkdir()
    for name in BLOCKED:
        stub = folder / name
        stub.write_text(f'#!/bin/sh\necho "{name} $*" >> "{folder}/calls.log"\nexit 1\n')
        stub.chmod(0o755)
    return folder


def _path_without_dpkg(folder: Path) -> str:
    """A PATH holding every command of the current PATH except dpkg/apt/sudo."""
    folder.mkdir()
    for d in os.environ["PATH"].split(os.pathsep):
        if not os.path.isdir(d):
            continue
        for entry in os.scandir(d):
            name = entry.name
            if name.startswith(("dpkg", "apt")) or name == "sudo" or (folder / name).exists():
                continue
            if os.access(entry.path, os.X_OK):
                (folder / name).symlink_to(entry.path)
    return str(folder)


def _env(**kw) -> dict:
    env = {k: v for k, v in os.environ.items()
           if k not in ("PETSC_DIR", "SLEPC_DIR", "PETSC_ARCH", "VIRTUAL_ENV", "PYTHONPATH",
                        "RAILVIB_SETUP_MODE")}
    env.update({k: str(v) for k, v in kw.items()})
    return env


def _setup(env: dict, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["bash", str(SETUP), *args], env=env, cwd=ROOT, capture_output=True,
                          text=True, timeout=900)


def _system_state() -> dict:
    """Modification times of what a system-wide install would touch."""
    paths = ["/var/lib/dpkg/status", "/usr/lib/python3/dist-packages",
             sysconfig.get_paths(vars={"base": "/usr/local", "platbase": "/usr/local"})
             ["purelib"]]
    return {p: os.stat(p).st_mtime_ns for p in paths if os.path.exists(p)}


@pytest.mark.slow
def test_own_stack_with_petsc_dir_installs_into_the_venv_only(tmp_path):
    petsc, slepc = _debian_dirs()
    stubs = _stubs(tmp_path / "stubs")
    venv = tmp_path / "venv"
    before = _system_state()
    env = _env(PATH=f"{stubs}{os.pathsep}{os.environ['PATH']}", PETSC_DIR=petsc,
               SLEPC_DIR=slepc, PYTHON=SYSTEM_PYTHON, VENV=venv)
    proc = _setup(env)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "[setup] ok: PETSc" in proc.stdout
    assert not (stubs / "calls.log").exists(), (stubs / "calls.log").read_text()
    assert _system_state() == before
    # the venv finds PETSc without anything exported (the .pth keeps the given dirs)
    check = subprocess.run(
        [str(venv / "bin" / "python"), "-c",
         "import petsc4py, slepc4py, railvib_hpc; petsc4py.init(); slepc4py.init(); "
         "from petsc4py import PETSc; import os; print(os.environ['PETSC_DIR'])"],
        env=_env(), capture_output=True, text=True, timeout=120)
    assert check.returncode == 0 and check.stdout.strip() == petsc, check.stderr
    # a second call does nothing (and still calls no package tool)
    again = _setup(env)
    assert again.returncode == 0 and again.stdout == "", again.stdout + again.stderr
    assert not (stubs / "calls.log").exists()


def test_own_stack_without_dpkg_names_what_is_missing_in_one_line(tmp_path):
    path = _path_without_dpkg(tmp_path / "bin")
    venv = tmp_path / "venv"
    # without PETSC_DIR, Debian's petsc4py/slepc4py are not importable: "missing"
    proc = _setup(_env(PATH=path, PYTHON=SYSTEM_PYTHON, VENV=venv))
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert lines[0].startswith("[setup] error: bring-your-own stack (no dpkg;")
    assert "missing petsc4py" in lines[0] and "slepc4py" in lines[0]
    assert "mpi4py" not in lines[0] and "h5py" not in lines[0]
    assert "nothing installed" in lines[0] and not venv.exists()


def test_own_stack_missing_h5py_is_named(tmp_path):
    petsc, slepc = _debian_dirs()
    stubs = _stubs(tmp_path / "stubs")
    shadow = tmp_path / "shadow" / "h5py"
    shadow.mkdir(parents=True)
    (shadow / "__init__.py").write_text("raise ImportError('h5py hidden by the test')\n")
    proc = _setup(_env(PATH=f"{stubs}{os.pathsep}{os.environ['PATH']}", PETSC_DIR=petsc,
                       SLEPC_DIR=slepc, PYTHON=SYSTEM_PYTHON, VENV=tmp_path / "venv",
                       PYTHONPATH=shadow.parent))
    assert proc.returncode == 2
    line, = proc.stderr.strip().splitlines()
    assert "missing h5py (h5py hidden by the test)" in line
    assert "petsc4py" not in line and not (tmp_path / "venv").exists()
    assert not (stubs / "calls.log").exists()


def test_unknown_option_is_refused():
    proc = _setup(_env(), "--tets")
    assert proc.returncode == 2
    assert proc.stderr.strip() == "[setup] error: unknown option '--tets' (allowed: --test)"


def test_own_stack_test_tools_need_pvbatch(tmp_path):
    """``--test`` in bring-your-own mode names a missing pvbatch (or honours the opt-out)."""
    path = _path_without_dpkg(tmp_path / "bin")
    (Path(path) / "pvbatch").unlink(missing_ok=True)
    env = _env(PATH=path, PYTHON=SYSTEM_PYTHON, VENV=tmp_path / "venv")
    proc = _setup(env, "--test")
    assert proc.returncode == 2
    line, = proc.stderr.strip().splitlines()
    assert "missing pvbatch (ParaView)" in line and "RAILVIB_SKIP_PARAVIEW=1" in line
    # opting out of the ParaView tests gets past the test tools to the stack check
    proc = _setup({**env, "RAILVIB_SKIP_PARAVIEW": "1"}, "--test")
    line, = proc.stderr.strip().splitlines()
    assert proc.returncode == 2 and "missing petsc4py" in line
