#!/usr/bin/env bash
# Idempotent setup behind `make`: a venv (.venv) with railvib-hpc (editable), the gmsh wheel,
# ruff and pytest on top of an MPI/PETSc/SLEPc/HDF5 stack. Users export nothing.
#
# Two ways to get the stack (docs/install.md):
#  * Debian 12 / Ubuntu 24.04 (dpkg present, PETSC_DIR and SLEPC_DIR unset): missing Debian
#    packages are installed with apt-get (as root or with sudo) and the venv is told where
#    Debian's PETSc/SLEPc live.
#  * Bring your own (PETSC_DIR or SLEPC_DIR set, or no dpkg: conda, environment modules,
#    Spack): the environment's petsc4py, slepc4py, mpi4py and h5py are used and nothing is
#    installed system-wide. What is missing is named in one line (exit 2).
#
# Usage: tools/setup.sh [--test]
#   --test   also the tools of the test suite: ParaView's pvbatch (Debian: python3-paraview;
#            bring your own: checked; RAILVIB_SKIP_PARAVIEW=1 opts out of the ParaView tests)
# Environment: VENV (default .venv); PYTHON (bring your own: the interpreter, default python3
# on PATH); RAILVIB_SETUP_MODE=debian|own to override the choice.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
WITH_TEST=0
for arg in "$@"; do
  case "$arg" in
    --test) WITH_TEST=1 ;;
    *) echo "[setup] error: unknown option '$arg' (allowed: --test)" >&2; exit 2 ;;
  esac
done

fail() { echo "[setup] error: $*" >&2; exit 2; }

# ---- which stack
MODE=${RAILVIB_SETUP_MODE:-}
WHY=""
if [ -z "$MODE" ]; then
  if [ -n "${PETSC_DIR:-}" ] || [ -n "${SLEPC_DIR:-}" ]; then
    MODE=own; WHY="PETSC_DIR/SLEPC_DIR set"
  elif ! command -v dpkg-query >/dev/null 2>&1; then
    MODE=own; WHY="no dpkg"
  else
    MODE=debian
  fi
fi
case "$MODE" in
  debian) PYTHON=/usr/bin/python3 ;;
  own) PYTHON=${PYTHON:-$(command -v python3 || true)}; WHY=${WHY:-RAILVIB_SETUP_MODE=own}
       [ -n "$PYTHON" ] || fail "bring-your-own stack ($WHY): missing python3 on PATH" ;;
  *) fail "RAILVIB_SETUP_MODE='$MODE' (allowed: debian, own)" ;;
esac

# ---- test tools (ParaView's pvbatch), before the stamp: quick when present
if [ "$WITH_TEST" = 1 ] && ! command -v pvbatch >/dev/null 2>&1 \
   && [ "${RAILVIB_SKIP_PARAVIEW:-0}" = 0 ]; then
  if [ "$MODE" = debian ]; then
    if dpkg-query -W -f='${Status}' python3-vtk9 2>/dev/null | grep -q "install ok installed"; then
      fail "python3-paraview (pvbatch, for tests/io/test_paraview.py) conflicts with the installed python3-vtk9: install ParaView yourself or set RAILVIB_SKIP_PARAVIEW=1"
    fi
    echo "[setup] installing Debian package python3-paraview (pvbatch, for the ParaView tests)"
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends \
      python3-paraview >/dev/null
  else
    fail "bring-your-own stack ($WHY): missing pvbatch (ParaView) for tests/io/test_paraview.py: conda install -c conda-forge paraview, a ParaView module, or set RAILVIB_SKIP_PARAVIEW=1"
  fi
fi

STAMP="$VENV/.railvib-setup-ok"
SIGNATURE="$MODE|$PYTHON|${PETSC_DIR:-}|${SLEPC_DIR:-}|${PETSC_ARCH:-}"
if [ -f "$STAMP" ] && [ "$STAMP" -nt pyproject.toml ] && [ "$STAMP" -nt tools/setup.sh ] \
   && [ "$(cat "$STAMP")" = "$SIGNATURE" ]; then
  exit 0
fi

if [ "$MODE" = debian ]; then
  APT_PKGS="python3-petsc4py python3-slepc4py python3-mpi4py python3-h5py-mpi python3-scipy python3-matplotlib python3-venv python3-pip openmpi-bin"
  missing=""
  for p in $APT_PKGS; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
  done
  if [ -n "$missing" ]; then
    echo "[setup] installing Debian packages:$missing"
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
  fi
  # PETSc/SLEPc of the Debian packages (real scalars): Debian 12 has 3.18, Ubuntu 24.04 3.19
  PETSC_DIR_USE=$(ls -d /usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real /usr/lib/petscdir/petsc3.*/*-real 2>/dev/null | head -n1)
  SLEPC_DIR_USE=$(ls -d /usr/lib/slepcdir/slepc3.*/x86_64-linux-gnu-real /usr/lib/slepcdir/slepc3.*/*-real 2>/dev/null | head -n1)
  if [ -z "$PETSC_DIR_USE" ] || [ -z "$SLEPC_DIR_USE" ]; then
    fail "PETSc/SLEPc directories not found under /usr/lib/petscdir, /usr/lib/slepcdir"
  fi
else
  # Bring your own: check the environment first, install nothing, name what is missing.
  PETSC_DIR_USE=${PETSC_DIR:-}
  SLEPC_DIR_USE=${SLEPC_DIR:-}
  launcher=""
  command -v mpiexec >/dev/null 2>&1 || command -v mpirun >/dev/null 2>&1 || launcher="mpiexec/mpirun (MPI launcher on PATH)"
  missing=$(LAUNCHER="$launcher" "$PYTHON" - <<'PY' 2>/dev/null || echo "a working Python 3.10+ ($PYTHON)"
import importlib, os, sys

missing = []


def check(name, probe):
    try:
        probe()
    except Exception as exc:  # any failure means: not usable
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        missing.append(f"{name} ({reason[:90]})")


def petsc():
    import petsc4py
    petsc4py.init([])
    from petsc4py import PETSc
    if not PETSc.Sys.hasExternalPackage("mumps"):
        missing.append("MUMPS in PETSc (the modal stage's shift-invert solver)")


def slepc():
    import slepc4py
    slepc4py.init([])
    from slepc4py import SLEPc  # noqa: F401


if sys.version_info < (3, 10):
    missing.append("Python >= 3.10 (this is %d.%d)" % sys.version_info[:2])
check("venv/ensurepip", lambda: [importlib.import_module(m) for m in ("venv", "ensurepip")])
check("mpi4py", lambda: importlib.import_module("mpi4py.MPI"))
check("petsc4py", petsc)
check("slepc4py", slepc)
check("h5py", lambda: importlib.import_module("h5py"))
if os.environ.get("LAUNCHER"):
    missing.append(os.environ["LAUNCHER"])
print(", ".join(missing))
PY
)
  if [ -n "$missing" ]; then
    fail "bring-your-own stack ($WHY; $PYTHON), nothing installed: missing $missing; see docs/install.md"
  fi
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating venv $VENV from $PYTHON (with its site packages)"
  "$PYTHON" -m venv --system-site-packages "$VENV"
fi
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
# Processed before Debian's petsc4py.pth (venv site-packages come first), so petsc4py finds
# PETSc; setdefault: a PETSC_DIR exported later (e.g. by a module) wins.
if [ -n "$PETSC_DIR_USE" ] || [ -n "$SLEPC_DIR_USE" ]; then
  {
    printf "import os"
    [ -n "$PETSC_DIR_USE" ] && printf "; os.environ.setdefault('PETSC_DIR', '%s')" "$PETSC_DIR_USE"
    [ -n "$SLEPC_DIR_USE" ] && printf "; os.environ.setdefault('SLEPC_DIR', '%s')" "$SLEPC_DIR_USE"
    [ -n "${PETSC_ARCH:-}" ] && printf "; os.environ.setdefault('PETSC_ARCH', '%s')" "$PETSC_ARCH"
    printf "\n"
  } > "$SITE/00_railvib_petsc.pth"
else
  rm -f "$SITE/00_railvib_petsc.pth"
fi
# Every pip install keeps the interpreter's own numpy and scipy: a dependency (SALib,
# gstools, ...) may otherwise pull newer wheels into the venv, and a numpy 2.x there breaks
# the system's h5py/petsc4py (built against its numpy). The pins are read from the
# interpreter each run (rewritten, so a system upgrade moves them too).
CONSTRAINTS="$VENV/railvib-constraints.txt"
"$PYTHON" - > "$CONSTRAINTS" <<'PY'
import importlib

for name in ("numpy", "scipy"):
    try:
        print(f"{name}=={importlib.import_module(name).__version__}")
    except ImportError:      # not in the system: pip chooses (bring your own, e.g. conda)
        pass
PY
echo "[setup] installing railvib-hpc (editable) and gmsh wheel into $VENV" \
     "(keeping $(tr '\n' ' ' < "$CONSTRAINTS"| sed 's/ $//'))"
"$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" --upgrade pip >/dev/null
# setuptools' editable build prints an information-only "Editable installation" notice
# (careful with folders named like the package) as a warning on every install: not shown
# (it was most of the first screen of `make run` on a fresh clone)
PYTHONWARNINGS="${PYTHONWARNINGS:+$PYTHONWARNINGS,}ignore:Editable installation:Warning" \
  "$VENV/bin/python" -m pip install -q -c "$CONSTRAINTS" -e ".[test]" ruff
"$VENV/bin/python" - <<'PY'
import os
os.environ["H5PY_ALWAYS_USE_MPI"] = "1"   # Debian's h5py: its MPI build, if installed
import petsc4py, slepc4py, mpi4py, h5py, gmsh, scipy, numpy
petsc4py.init(); slepc4py.init()
from petsc4py import PETSc
from slepc4py import SLEPc
import railvib_hpc
print("[setup] ok: PETSc %s, SLEPc %s, gmsh %s, numpy %s, scipy %s, h5py %s (%s)" % (
    ".".join(map(str, PETSc.Sys.getVersion())), ".".join(map(str, SLEPc.Sys.getVersion())),
    gmsh.__version__, numpy.__version__, scipy.__version__, h5py.__version__,
    "MPI" if h5py.get_config().mpi else "serial: HDF5 writes are gathered to rank 0"))
PY
printf '%s' "$SIGNATURE" > "$STAMP"
