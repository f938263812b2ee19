"""Where railvib may write its results: not into its own source tree, not over files it
did not write.

An output folder (``--out``, a study's folder and its variants' folders) is refused, in one
line before anything is written (:func:`refuse_foreign_folder`, called where a command
takes the folder's lock, :func:`railvib_hpc.io.locks.acquire_lock`), when

* it is, or lies inside, railvib's own files: the installed package (``railvib_hpc/``),
  and in a source checkout (the package's parent holds railvib-hpc's ``pyproject.toml``)
  the checkout's root and its project folders (:data:`PROJECT_FOLDERS`: ``docs``,
  ``jobs``, ``tests``, ...). ``--out docs`` wrote some 20 result files among the project's
  documentation without a word. The checkout's ``results/`` (the default ``--out``) and
  any other folder stay allowed;
* it exists, holds no record of railvib (:data:`~railvib_hpc.io.files.RECORD_DIR`, which
  every command that writes creates first) and holds a file of a name railvib writes
  (:data:`~railvib_hpc.io.files.OUTPUT_NAMES`: ``report.md``, ``mesh.msh``,
  ``run.json``...): someone else's file, which the run would overwrite. A folder railvib
  wrote before, an empty or new one, and one that holds other things (the case file,
  notes) are fine: railvib adds its files beside them.

There is no option to force it: choose a new folder, or move the files away.
"""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import UserError
from .files import OUTPUT_NAMES, RECORD_DIR

#: The package's folder (``railvib_hpc/``).
PACKAGE = Path(__file__).resolve().parents[1]
#: The folders of a source checkout that are the project itself (its source, tests,
#: documentation, jobs, tools, CI and version control); ``results/`` is not one of them.
PROJECT_FOLDERS = (PACKAGE.name, "docs", "jobs", "tests", "tools", "bench", "examples",
                   "meshes", ".ci", ".git")


class OutputFolderError(UserError):
    """An output folder railvib must not write into (its own files, or someone else's)."""


def checkout_root(package: Path = PACKAGE) -> Path | None:
    """The source checkout the package lies in (None when installed elsewhere)."""
    project = package.parent / "pyproject.toml"
    try:
        text = project.read_text()
    except OSError:
        return None
    return package.parent if 'name = "railvib-hpc"' in text else None


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def own_folder_problem(out_dir: str | os.PathLike, package: Path = PACKAGE) -> str | None:
    """Why ``out_dir`` is railvib's own (its package, or its checkout's root or project
    folders); None when it is not.

    Examples
    --------
    >>> own_folder_problem(PACKAGE / "docs_out")  # doctest: +ELLIPSIS
    "... is inside railvib's own package folder ..."
    """
    path = Path(os.path.abspath(out_dir))
    real = path.resolve()
    root = checkout_root(package)
    own = [(package.resolve(), "package folder")]
    if root is not None:
        own += [(root.resolve() / name, f"project folder {name}/") for name in PROJECT_FOLDERS]
    for folder, what in own:
        if _inside(real, folder):
            return (f"{path} is inside railvib's own {what} ({folder}): results go to a "
                    "folder of their own (the default results/<case.name>, or a new "
                    "folder), never among the project's files")
    if root is not None and real == root.resolve():
        return (f"{path} is railvib's own source checkout: results go to a folder of their "
                "own (the default results/<case.name>, or a new folder)")
    return None


def foreign_files_problem(out_dir: str | os.PathLike) -> str | None:
    """Why ``out_dir`` holds someone else's files of railvib's names (None: it does not,
    or railvib's record is in it)."""
    path = Path(os.path.abspath(out_dir))
    if not path.is_dir() or (path / RECORD_DIR).is_dir():
        return None
    try:
        foreign = sorted(e.name for e in os.scandir(path) if e.name in OUTPUT_NAMES)
    except OSError:
        return None                              # (the lock reports an unusable folder)
    if not foreign:
        return None
    shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3
                                      else "")
    return (f"{path} holds {shown}, which railvib did not write (no {RECORD_DIR}/ record "
            "in it) and a run would overwrite: choose a new or empty folder, or move "
            "those files away")


def output_folder_problem(out_dir: str | os.PathLike, package: Path = PACKAGE) -> str | None:
    """Why railvib must not write into ``out_dir`` (None: it may); see the module notes."""
    return own_folder_problem(out_dir, package) or foreign_files_problem(out_dir)


def refuse_foreign_folder(out_dir: str | os.PathLike, own_only: bool = False) -> None:
    """Raise :class:`OutputFolderError` when railvib must not write into ``out_dir``
    (``own_only``: only when it is railvib's own, e.g. the parent of a study's folder,
    where railvib adds a folder and overwrites nothing)."""
    problem = own_folder_problem(out_dir) if own_only else output_folder_problem(out_dir)
    if problem is not None:
        raise OutputFolderError(f"output folder {problem}")
