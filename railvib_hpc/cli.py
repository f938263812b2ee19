"""Command line: ``railvib COMMAND CASE.toml [--out DIR] [--set key=value ...] [--wait]
[-- PETSc options]``.

A thin shell over the Python API (:mod:`railvib_hpc.api`): the CLI parses the arguments,
loads the case, takes the output folder's lock, calls :class:`~railvib_hpc.api.Pipeline`
or :func:`~railvib_hpc.api.run_study`, and turns their results and errors into printed
lines and exit codes. Everything else lives in the API and the stages.

Exit codes (the same on every MPI rank):

* 0 -- success (for ``run``: the pipeline completed; the verdict is in the table);
* 2 -- a user or environment error: bad case file or value, a stale, foreign or corrupt
  input file, an output folder in use by another run, a full disk, missing permissions,
  a bad PETSc option; one line on stderr, no traceback;
* 1 -- an internal error (a bug): one line asking to report it, naming a log file with
  the traceback (``<out>/.railvib/crash-<time>-<pid>.log``);
* 141 -- the output's reader went away (``railvib check CASE | head -1``), nothing else.
"""

from __future__ import annotations

import argparse
import contextlib
import datetime
import os
import sys
import tempfile
import traceback
from pathlib import Path

from . import __version__
from .config import Case, load_case, results_folder_name
from .errors import CaseError, UserError
from .io.files import RECORD_DIR, TRANSIENT_DIR
from .log import Reporter
from .parallel import RootFailure, on_root, world
from .pipeline import PIPELINES, single_stage_commands
from .studies.registry import study_helps

#: Exit code when the output's reader goes away (a closed pipe): the shell's 128 + SIGPIPE.
BROKEN_PIPE_EXIT = 141


#: The help layout of ``railvib study --help``: the studies' lines as given.
RAW = argparse.RawDescriptionHelpFormatter

#: The help lines of the commands that run a pipeline of stages (:data:`PIPELINES`).
PIPELINE_HELPS = {
    "run": "the whole pipeline: " + ", ".join(PIPELINES["run"]),
    "transient": "direct time integration of the full FE model (absorbing faces, causal "
                 "waves), then assess; results in --out itself (default: "
                 "results/<case.name>/transient)",
}


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="railvib",
        description="Train-induced vibration of buildings next to railway tracks "
                    "(gmsh + PETSc/SLEPc + reduced multibody dynamics).",
        epilog="Options after a bare '--' are passed to PETSc/SLEPc, e.g. "
               "'-- -railvib_eig_st_ksp_type preonly -log_view'; options that nothing used "
               "are reported at the end. Exit codes: 0 success, 2 user or environment "
               "error (one line), 1 internal error (please report; a log file is named).")
    p.add_argument("--version", action="version", version=f"railvib-hpc {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    studies = study_helps()                  # the studies' registry: names and help lines
    helps = {"check": "validate a case file (no computation)", **single_stage_commands(),
             **PIPELINE_HELPS, "study": "the studies: " + " / ".join(studies)}
    width = max(map(len, studies), default=0)
    for name, text in helps.items():
        if name == "study":                 # one line per study, as the registry has it
            sp = sub.add_parser(name, help=text, formatter_class=RAW, description="\n".join(
                ["run the variants of a study, then merge them into its report:",
                 *(f"  {k:<{width}}  {h}" for k, h in studies.items())]))
        else:
            sp = sub.add_parser(name, help=text, description=text)
        if name == "study":
            sp.add_argument("kind", choices=list(studies),
                            help="which study: " + ", ".join(studies))
            sp.add_argument("--variant", action="append", default=[], metavar="NAME|INDEX",
                            help="compute only this variant (repeatable; 0-based index in "
                                 "--list order, e.g. an array-job task id); no report")
            sp.add_argument("--merge", action="store_true",
                            help="compute nothing: write the report from finished variants")
            sp.add_argument("--prepare", action="store_true",
                            help="compute only the shared model (modes, speed studies)")
            sp.add_argument("--list", action="store_true",
                            help="list the variants, their overrides and status")
            sp.add_argument("--study-set", dest="study_set", action="append", default=[],
                            metavar="KEY=VALUE",
                            help="study setting, e.g. --study-set levels=[0.5,0.75,1] "
                                 "(repeatable; see jobs/README.md)")
        sp.add_argument("case", help="case file (TOML)")
        sp.add_argument("--out", type=Path, default=None,
                        help="output folder (default: results/<case.name>"
                             + ("/transient)" if name == "transient" else ")"))
        sp.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="override a case key, e.g. --set mesh.refinement=2 (repeatable)")
        if name != "check":
            sp.add_argument("--wait", action="store_true",
                            help="wait for another railvib command that uses the same output "
                                 "folder instead of stopping")
    return p


def _split_petsc(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--" in argv:
        k = argv.index("--")
        return argv[:k], argv[k + 1:]
    return argv, []


def _out_dir(args: argparse.Namespace, case: Case, rep: Reporter) -> Path:
    if args.out is not None:
        return args.out
    name = results_folder_name(case["case.name"])
    if name != case["case.name"]:
        rep.info(f"note: case.name = {case['case.name']!r} is not a plain folder name; the "
                 f"results go to results/{name}")
    default = Path("results") / name
    return default / TRANSIENT_DIR if args.command == "transient" else default


def _cmd_check(case: Case, rep: Reporter) -> int:
    from .mesh.layout import build_layout

    lay = build_layout(case)
    rep.info(f"case '{case['case.name']}' is valid (preset '{case['case.preset']}', "
             f"file {case.path or '<defaults>'})")
    if case["track.count"]:
        rep.info(f"  track: {len(lay.sleeper_x)} sleepers, flexible rail "
                 f"{case['track.rail_length']:g} m, {lay.rail_div} rail elements per bay")
    else:
        ld = case["load"]
        rep.info(f"  track: none (track.count = 0): the bare soil under {len(ld['offsets'])} "
                 f"moving load(s) of {ld['force']:g} N at {ld['speed']:g} m/s on y = "
                 f"{ld['y']:g} m from x = {ld['x_start']:g} m ("
                 + (f"static start, run-up {ld['ramp_time']:g} s" if ld["start"] == "static"
                    else f"ramp {ld['ramp_time']:g} s") + f", half-width {ld['half_width']:g} m"
                 + (f", harmonic at {ld['frequency']:g} Hz" if ld["frequency"] else "") + ")")
    from .mbs.case_vehicle import tracks_line

    tracks = tracks_line(case)
    if tracks:
        rep.info(f"  tracks: {tracks}")
    rep.info(f"  mesh: {len(lay.blocks)} structured blocks, refinement {case['mesh.refinement']:g}"
             + (f", from file {case['mesh.file']}" if case["mesh.file"] else ""))
    from .mesh.building import building_line
    from .mesh.interfaces import site_line
    from .site import soil_layers

    rep.info(f"  building: {building_line(case)}")
    from .mesh.turn import turn_line

    turned = turn_line(case)
    if turned:
        rep.info(f"  {turned}")
    if case["track.count"]:
        rep.info(f"  track bed: {site_line(case)}")
    z1 = case["geometry.z1"]
    for x in soil_layers(case):
        rep.info(f"  soil: {x['part']} {z1 - x['z_top']:g}-{z1 - x['z_bottom']:g} m deep, "
                 f"c_S {x['c_s']:.4g} m/s, rho {x['rho']:g} kg/m^3, nu {x['nu']:g}")
    for section, what in (("trench", "trench"), ("wib", "wave-impeding block")):
        if case[f"{section}.type"] != "none":
            rep.info(f"  {what}: " + ", ".join(f"{k} {v}" for k, v in case[section].items()))
    from .site import site_lines

    for line in site_lines(case):                 # [site] keys given, [[probes.line]]
        rep.info(f"  {line}")
    return 0


def _dispatch(args: argparse.Namespace, case: Case, out: Path, comm, rep: Reporter,
              petsc_options: list[str], command: str) -> tuple[int, list[str]]:
    """Run the command; returns the exit code and the PETSc options nothing used."""
    from .api import Pipeline, run_study
    from .petsc_env import unused_options

    if args.command == "check":
        return _cmd_check(case, rep), unused_options(petsc_options)
    if args.command == "study":
        study = run_study(args.kind, case, out, comm, variants=args.variant,
                          merge_only=args.merge, prepare=args.prepare, list_only=args.list,
                          study_set=args.study_set, petsc_options=petsc_options,
                          wait=args.wait, reporter=rep)
        return (0 if study.ok else 2), list(study.unused_petsc_options)
    pipe = Pipeline(case, out, comm, petsc_options, reporter=rep, wait=args.wait,
                    command=command)
    with pipe.session(" ".join(["railvib", args.command, str(args.case)])) as unused:
        if args.command in PIPELINES:
            _cmd_check(case, rep)
            assess = pipe.run_stages(PIPELINES[args.command])["assess"]
            rep.info("\n" + rep.timing_table())
            failed = assess.exceeded
            what = "pipeline" if args.command == "run" else args.command
            rep.info(f"{what} complete: {len(assess.verdict)} probes assessed, "
                     + (f"limits exceeded at {', '.join(failed)}" if failed
                        else "no limit exceeded"))
        else:
            pipe.stage(args.command)
            if args.command != "mesh":
                rep.info("\n" + rep.timing_table())
    return 0, list(unused)


def run(argv: list[str] | None = None) -> int:
    """Parse arguments and run a command; returns the exit code (raises nothing for user
    or internal errors: both are reported in one line)."""
    from .petsc_env import (
        check_option_words,
        clear_options,
        petsc_error_text,
        petsc_error_type,
    )

    argv = list(sys.argv[1:] if argv is None else argv)
    command = " ".join(["railvib", *argv])
    argv, petsc_options = _split_petsc(argv)
    args = _parser().parse_args(argv)
    comm = world()
    rep = Reporter(comm.rank)
    out: Path | None = None
    try:
        check_option_words(petsc_options)
        case = on_root(lambda: load_case(args.case, args.overrides))
        for note in case.notes:
            rep.info(f"note: {note}")
        from .validation import command_problems

        # what the command's stages refuse (their Stage.refusals), before anything is
        # written or meshed: one line, exit 2
        problems = command_problems(case, args.command)
        if problems:
            raise CaseError(problems)
        out = _out_dir(args, case, rep)
        if args.command != "check" and not getattr(args, "list", False):
            from .io.out_folder import refuse_foreign_folder

            # a study adds out/<kind>/ and overwrites nothing in out itself
            on_root(lambda: refuse_foreign_folder(out, own_only=args.command == "study"))
        code, unused = _dispatch(args, case, out, comm, rep, petsc_options, command)
        if unused:
            _warn(comm, f"railvib {args.command}: warning: PETSc options after '--' that "
                        f"nothing used: {' '.join(unused)} (misspelt, or nothing was solved "
                        "with PETSc)")
        return code
    except UserError as exc:
        if comm.rank == 0:
            print(f"railvib {args.command}: error: {exc}", file=sys.stderr, flush=True)
        return exc.exit_code
    except BrokenPipeError:
        # whoever read the output went away (e.g. `railvib check CASE | head -1`): not a bug;
        # later writes go nowhere instead of raising again at exit
        with contextlib.suppress(OSError):
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (open for the rest of the process)
        return BROKEN_PIPE_EXIT
    except Exception as exc:
        petsc_error = petsc_error_type()
        if petsc_error is not None and isinstance(exc, petsc_error) and petsc_options:
            if comm.rank == 0:
                print(f"railvib {args.command}: error: PETSc stopped: {petsc_error_text(exc)}; "
                      f"check the options after '--': {' '.join(petsc_options)}",
                      file=sys.stderr, flush=True)
            return 2
        return _internal_error(args, out, comm, exc)
    finally:
        clear_options(petsc_options)


def _warn(comm, text: str) -> None:
    if comm.rank == 0:
        print(text, file=sys.stderr, flush=True)


def _internal_error(args: argparse.Namespace, out: Path | None, comm, exc: Exception) -> int:
    """One "please report" line naming a log file with the traceback; exit code 1."""
    if isinstance(exc, RootFailure):        # rank 0 has the original and reports it
        return 1
    stamp = datetime.datetime.now().strftime("%Y%m%d-%H%M%S")
    name = f"crash-{stamp}-{os.getpid()}" + (f"-rank{comm.rank}" if comm.rank else "") + ".log"
    text = (f"railvib {__version__}, command: railvib {' '.join(sys.argv[1:]) or args.command}"
            f"\nrank {comm.rank} of {comm.size}, python {sys.version.split()[0]}\n\n"
            + "".join(traceback.format_exception(exc)))
    log = None
    candidates = ([out / RECORD_DIR] if out is not None else []) + [Path(tempfile.gettempdir())]
    for folder in candidates:
        try:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / name).write_text(text)
            log = folder / name
            break
        except OSError:
            continue
    where = f"the traceback is in {log}" if log else "the traceback follows:\n" + text
    print(f"railvib {args.command}: internal error ({type(exc).__name__}: "
          f"{(str(exc).splitlines() or [''])[0]}) on rank {comm.rank}: this is a bug, please "
          f"report it with the log; {where}", file=sys.stderr, flush=True)
    return 1


def main() -> int:
    """Console-script entry point."""
    return run()
