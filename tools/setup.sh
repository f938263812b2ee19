#!/usr/bin/env bash
# Idempotent setup for Debian 12: system HPC stack, venv with system site packages,
# editable install, PETSC_DIR/SLEPC_DIR wiring. Called by `make` (users export nothing).
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
SYSPY=/usr/bin/python3
STAMP="$VENV/.railvib-setup-ok"

if [ -f "$STAMP" ] && [ "$STAMP" -nt pyproject.toml ] && [ "$STAMP" -nt tools/setup.sh ]; then
  exit 0
fi

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

# Locate PETSc/SLEPc of the Debian packages (real scalars).
PETSC_DIR_FOUND=${PETSC_DIR:-$(ls -d /usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real /usr/lib/petscdir/petsc3.*/*-real 2>/dev/null | head -n1)}
SLEPC_DIR_FOUND=${SLEPC_DIR:-$(ls -d /usr/lib/slepcdir/slepc3.*/x86_64-linux-gnu-real /usr/lib/slepcdir/slepc3.*/*-real 2>/dev/null | head -n1)}
if [ -z "$PETSC_DIR_FOUND" ] || [ -z "$SLEPC_DIR_FOUND" ]; then
  echo "[setup] error: PETSc/SLEPc directories not found under /usr/lib/petscdir, /usr/lib/slepcdir" >&2
  exit 1
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating venv $VENV (with system site packages)"
  $SYSPY -m venv --system-site-packages "$VENV"
fi
SITE=$("$VENV/bin/python" -c 'import sysconfig; print(sysconfig.get_paths()["purelib"])')
# Processed before Debian's petsc4py.pth (venv site-packages come first), so petsc4py finds PETSc.
cat > "$SITE/00_railvib_petsc.pth" <<PTH
import os; os.environ.setdefault('PETSC_DIR', '$PETSC_DIR_FOUND'); os.environ.setdefault('SLEPC_DIR', '$SLEPC_DIR_FOUND')
PTH
echo "[setup] installing railvib-hpc (editable) and gmsh wheel"
"$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
"$VENV/bin/python" -m pip install -q -e ".[test]" ruff
"$VENV/bin/python" - <<'PY'
import petsc4py, slepc4py, mpi4py, h5py, gmsh, scipy, numpy
petsc4py.init(); slepc4py.init()
from petsc4py import PETSc
from slepc4py import SLEPc
print("[setup] ok: PETSc %s, SLEPc %s, gmsh %s, numpy %s, scipy %s" % (
    ".".join(map(str, PETSc.Sys.getVersion())), ".".join(map(str, SLEPc.Sys.getVersion())),
    gmsh.__version__, numpy.__version__, scipy.__version__))
PY
touch "$STAMP"
