"""Initialise petsc4py/slepc4py with the user's options, finding Debian's PETSc if needed."""

from __future__ import annotations

import contextlib
import glob
import os
import sys
from collections.abc import Iterator, Mapping, Sequence


def _debian_dir(pattern: str) -> str | None:
    found = sorted(glob.glob(pattern))
    return found[-1] if found else None


def init_petsc(options: list[str] | None = None) -> None:
    """Initialise PETSc and SLEPc once, passing ``options`` (e.g. ``-log_view``).

    When PETSc is already initialised in this process, the options are inserted into its
    database (:func:`clear_options` removes them again).

    If ``PETSC_DIR``/``SLEPC_DIR`` are unset and Debian's packages are installed, they are
    pointed at ``/usr/lib/petscdir/petsc3.*/x86_64-linux-gnu-real`` (and ``slepcdir``) and
    Debian's petsc4py is put on ``sys.path``; cluster users' own settings are left alone.
    """
    if "petsc4py.PETSc" in sys.modules:
        if options:                          # initialised earlier in this process (tests)
            from petsc4py import PETSc

            PETSc.Options().insertString(" ".join(options))
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


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


def check_option_words(options: list[str]) -> None:
    """Refuse words after ``--`` that are neither a PETSc option nor the value of one.

    PETSc options are ``-name`` with at most one value (``-name value``); a second word,
    or a first word without ``-``, would be silently ignored by PETSc.

    Raises
    ------
    UserError
        Naming the stray word.
    """
    from .errors import UserError

    value_allowed = False
    for word in options:
        if word.startswith("-") and len(word) > 1 and not _is_number(word):
            value_allowed = True
        elif value_allowed:
            value_allowed = False
        else:
            raise UserError(f"'{word}' after '--' is neither a PETSc option (-name) nor the "
                            "value of one (each option takes at most one value), e.g. "
                            "'-- -railvib_eig_st_ksp_type preonly -log_view'")


def _option_names(options: list[str]) -> list[str]:
    return [w[1:] for w in options if w.startswith("-") and len(w) > 1 and not _is_number(w)]


def _petsc_library():
    """The loaded PETSc shared library (ctypes), or None."""
    import ctypes

    try:
        with open("/proc/self/maps") as f:
            paths = {line.split()[-1] for line in f if "libpetsc" in line and ".so" in line}
    except OSError:
        return None
    for path in sorted(paths):
        try:
            lib = ctypes.CDLL(path)
            lib.PetscOptionsLeftGet  # noqa: B018 - presence check
            return lib
        except (OSError, AttributeError):
            continue
    return None


def _left_options() -> set[str] | None:
    """Names of the options in PETSc's database that nothing has queried (None: unknown)."""
    import ctypes

    import numpy as np
    from petsc4py import PETSc

    lib = _petsc_library()
    if lib is None:
        return None
    int_t = ctypes.c_int64 if np.dtype(PETSc.IntType).itemsize == 8 else ctypes.c_int32
    n = int_t(0)
    names = ctypes.POINTER(ctypes.c_char_p)()
    values = ctypes.POINTER(ctypes.c_char_p)()
    lib.PetscOptionsLeftGet.argtypes = [ctypes.c_void_p, ctypes.POINTER(int_t),
                                        ctypes.POINTER(ctypes.POINTER(ctypes.c_char_p)),
                                        ctypes.POINTER(ctypes.POINTER(ctypes.c_char_p))]
    if lib.PetscOptionsLeftGet(None, ctypes.byref(n), ctypes.byref(names),
                               ctypes.byref(values)) != 0:
        return None
    left = {names[i].decode().lstrip("-") for i in range(n.value)}
    lib.PetscOptionsLeftRestore.argtypes = lib.PetscOptionsLeftGet.argtypes
    lib.PetscOptionsLeftRestore(None, ctypes.byref(n), ctypes.byref(names),
                                ctypes.byref(values))
    return left


#: Options PETSc reads only when it finalizes (never "used" before).
_READ_AT_FINALIZE = ("log_view", "log_summary", "options_left", "malloc_dump", "memory_view",
                     "malloc_view", "objects_dump", "log_trace", "log_all")


def unused_options(options: list[str]) -> list[str]:
    """The options given after ``--`` that PETSc has not used (so far) in this process.

    When PETSc was never initialised, all of them. Options PETSc reads at finalization
    (``-log_view`` ...) count as used.
    """
    names = _option_names(options)
    if "petsc4py.PETSc" not in sys.modules:
        return [f"-{n}" for n in names]
    from petsc4py import PETSc

    left = _left_options()
    opts = PETSc.Options()
    return [f"-{n}" for n in names if not n.startswith(_READ_AT_FINALIZE)
            and (not opts.hasName(n) or (left is not None and n in left))]


def clear_options(options: list[str]) -> None:
    """Remove the given options from PETSc's database again (a process that runs several
    commands, e.g. tests, does not carry them on)."""
    if "petsc4py.PETSc" not in sys.modules:
        return
    from petsc4py import PETSc

    opts = PETSc.Options()
    for n in _option_names(options):
        if not n.startswith(_READ_AT_FINALIZE) and opts.hasName(n):
            opts.delValue(n)


def petsc_error_type():
    """``petsc4py.PETSc.Error`` when petsc4py is loaded, else None."""
    mod = sys.modules.get("petsc4py.PETSc")
    return getattr(mod, "Error", None) if mod is not None else None


def petsc_error_text(exc: BaseException) -> str:
    """PETSc's own words for a ``PETSc.Error`` (the specific message of the last error, else
    the generic text of its code)."""
    import ctypes

    ierr = int(getattr(exc, "ierr", 0) or 0)
    lib = _petsc_library()
    if lib is None or not ierr:
        return f"error code {ierr}"
    text, specific = ctypes.c_char_p(), ctypes.c_char_p()
    lib.PetscErrorMessage.argtypes = [ctypes.c_int, ctypes.POINTER(ctypes.c_char_p),
                                      ctypes.POINTER(ctypes.c_char_p)]
    if lib.PetscErrorMessage(ierr, ctypes.byref(text), ctypes.byref(specific)) != 0:
        return f"error code {ierr}"
    words = (specific.value or text.value or b"").decode(errors="replace").strip()
    return f"{words} (error code {ierr})" if words else f"error code {ierr}"


def option_words(options: Sequence[str] | Mapping[str, object] | None) -> list[str]:
    """PETSc options as command-line words (a new list; the argument is never changed).

    A mapping gives ``{name: value}`` (``None`` or ``""`` for a flag), names with or
    without the leading ``-``.

    Examples
    --------
    >>> option_words({"railvib_eig_st_ksp_type": "preonly", "-log_view": None})
    ['-railvib_eig_st_ksp_type', 'preonly', '-log_view']
    >>> option_words(("-log_view",))
    ['-log_view']
    """
    if options is None:
        return []
    if isinstance(options, str):
        return options.split()
    if isinstance(options, Mapping):
        words: list[str] = []
        for name, value in options.items():
            words.append(name if str(name).startswith("-") else f"-{name}")
            if value is not None and value != "":
                words.append(str(value))
        return words
    return [str(w) for w in options]


@contextlib.contextmanager
def options_scope(options: Sequence[str]) -> Iterator[list[str]]:
    """Keep ``options`` in PETSc's database only for the block (the stages insert them when
    they start PETSc); on leaving, remove them again.

    Yields a list that, after the block, holds the options nothing used (see
    :func:`unused_options`), so the caller can warn about typos.

    Examples
    --------
    >>> with options_scope(["-no_such_option_anywhere"]) as unused:
    ...     pass
    >>> unused
    ['-no_such_option_anywhere']
    """
    words = list(options)
    unused: list[str] = []
    try:
        yield unused
        unused.extend(unused_options(words))
    finally:
        clear_options(words)
