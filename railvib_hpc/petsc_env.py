"""Initialise petsc4py/slepc4py with the user's options, finding Debian's PETSc if needed."""

from __future__ import annotations

import glob
import os
import sys


def _debian_dir(pattern: str) -> str | None:
    found = sorted(glob.glob(pattern))
    return found[-1] if found else None


def init_petsc(options: list[str] | None = None) -> None:
    """Initialise PETSc and SLEPc once, passing ``options`` (e.g. ``-log_view``).

    If ``PETSC_DIR``/``SLEPC_DIR`` are unset and Debian's packages are installed, they are
    pointed at ``/usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real`` (and ``slepcdir``) and
    Debian's petsc4py is put on ``sys.path``; cluster users' own settings are left alone.
    """
    if "petsc4py.PETSc" in sys.modules:
        return
    for var, pattern in (("PETSC_DIR", "/usr/lib/petscdir/petsc3.*/*-real"),
                         ("SLEPC_DIR", "/usr/lib/slepcdir/slepc3.*/*-real")):
        d = None if os.environ.get(var) else _debian_dir(pattern)
        if d:
            os.environ[var] = d
            path = os.path.join(d, "lib", "python3", "dist-packages")
            if os.path.isdir(path) and path not in sys.path:
                sys.path.append(path)
    import petsc4py

    petsc4py.init(["railvib", *(options or [])])
    import slepc4py

    slepc4py.init(["railvib", *(options or [])])
