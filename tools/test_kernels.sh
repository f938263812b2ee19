#!/usr/bin/env bash
# `make test-kernels`: the numerically sensitive test files under the BLAS kernels of other
# CPUs. Debian's OpenBLAS picks its compute kernel per CPU at run time, and a kernel of
# another vector width sums in another order: a test that sits within round-off of a
# threshold passes on one CPU and fails on the next (docs/verification.md). OPENBLAS_CORETYPE
# makes OpenBLAS run the named kernel on this CPU, so one machine checks them all.
#
# Usage: tools/test_kernels.sh PYTHON [pytest args...] -- FILE...
#   KERNELS (environment): the kernels, default "SkylakeX Haswell Sandybridge" (AVX-512,
#   AVX2 + FMA, AVX: the three vector widths; OpenBLAS's Zen target runs Haswell's double
#   precision kernels: every result of the modal tests came out bit for bit the same with
#   both). Skipped with a line saying why: this CPU's own kernel (make test ran it), a
#   kernel whose instructions the CPU lacks (it would die of SIGILL), one the BLAS ignores.
# One pytest pass per kernel over the files, the quick tier ("not slow and not mpi"); the
# first failing kernel ends the run with pytest's exit code.
set -uo pipefail
cd "$(dirname "$0")/.."
PYTHON=$1; shift
ARGS=()
while [ $# -gt 0 ] && [ "$1" != "--" ]; do ARGS+=("$1"); shift; done
[ "${1:-}" = "--" ] && shift
FILES=("$@")
[ ${#FILES[@]} -gt 0 ] || { echo "[test-kernels] error: no test files given" >&2; exit 2; }
KERNELS=${KERNELS:-SkylakeX Haswell Sandybridge}

flags=" $(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null | cut -d: -f2) "
needs() {   # the CPU flags a kernel's instructions need
  case "$1" in
    SkylakeX|Cooperlake) echo "avx512f avx512cd avx512bw avx512dq avx512vl" ;;
    Haswell|Zen) echo "avx2 fma" ;;
    Sandybridge) echo "avx" ;;
    *) echo "" ;;
  esac
}

# The kernel OpenBLAS runs (numpy's BLAS, which PETSc shares): openblas_get_corename.
CORENAME='
import ctypes, numpy  # noqa: F401  (loads the BLAS)
libs = {ln.split()[-1] for ln in open("/proc/self/maps") if "blas" in ln.lower()}
for path in sorted(libs):
    try:
        f = ctypes.CDLL(path).openblas_get_corename
    except (OSError, AttributeError):
        continue
    f.restype = ctypes.c_char_p
    print(f().decode())
    break
'

native=$(env -u OPENBLAS_CORETYPE "$PYTHON" -c "$CORENAME" 2>/dev/null)
t_all=$(date +%s)
for k in $KERNELS; do
  if [ "${native,,}" = "${k,,}" ]; then
    echo "[test-kernels] skipping OPENBLAS_CORETYPE=$k: this CPU's own kernel (make test ran it)"
    continue
  fi
  missing=""
  for f in $(needs "$k"); do
    case "$flags" in *" $f "*) ;; *) missing="$missing $f" ;; esac
  done
  if [ -n "$missing" ]; then
    echo "[test-kernels] skipping OPENBLAS_CORETYPE=$k: this CPU lacks$missing"
    continue
  fi
  running=$(OPENBLAS_CORETYPE=$k "$PYTHON" -c "$CORENAME" 2>/dev/null)
  if [ "${running,,}" != "${k,,}" ]; then
    echo "[test-kernels] skipping OPENBLAS_CORETYPE=$k: the BLAS runs '${running:-?}'" \
         "(not OpenBLAS with DYNAMIC_ARCH, or it does not know $k)"
    continue
  fi
  echo "[test-kernels] OPENBLAS_CORETYPE=$k: ${#FILES[@]} files"
  t0=$(date +%s)
  OPENBLAS_CORETYPE=$k "$PYTHON" -m pytest "${ARGS[@]}" -m "not slow and not mpi" \
    -p no:cacheprovider "${FILES[@]}"
  rc=$?
  if [ $rc -ne 0 ]; then
    echo "[test-kernels] OPENBLAS_CORETYPE=$k failed (exit $rc)" >&2
    exit $rc
  fi
  echo "[test-kernels] OPENBLAS_CORETYPE=$k passed in $(( $(date +%s) - t0 )) s"
done
echo "[test-kernels] done in $(( $(date +%s) - t_all )) s"
