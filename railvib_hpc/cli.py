"""Command line: ``railvib COMMAND CASE.toml [--out DIR] [--set key=value ...] [-- PETSc options]``.

Exit codes: 0 success, 2 user error (bad case file, bad mesh), 3 a stage that is
not implemented yet, 1 anything else (a bug: the traceback is printed).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from . import __version__
from .config import Case, load_case
from .errors import UserError
from .log import Reporter
from .parallel import on_root, world

STAGES = ("mesh", "modal", "mbs", "reconstruct", "assess")
STUDIES = ("convergence", "modes", "reflection", "speed")


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="railvib",
        description="Train-induced vibration of buildings next to railway tracks "
                    "(gmsh + PETSc/SLEPc + reduced multibody dynamics).",
        epilog="Options after a bare '--' are passed to PETSc/SLEPc, e.g. "
               "'-- -railvib_eig_eps_tol 1e-10 -log_view'.")
    p.add_argument("--version", action="version", version=f"railvib-hpc {__version__}")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    helps = {
        "check": "validate a case file (no computation)",
        "mesh": "build the gmsh model, check its quality, write mesh.msh/.h5/.xdmf",
        "modal": "assemble K, M and extract mass-normalised modes",
        "mbs": "roll the vehicle over the flexible track in modal coordinates",
        "reconstruct": "rebuild displacement/velocity/acceleration fields of every node",
        "assess": "evaluate the building response against vibration standards",
        "run": "the whole pipeline: mesh, modal, mbs, reconstruct, assess",
        "transient": "direct time integration of the full FE model (absorbing faces, "
                     "causal waves), then assess; results in <out>/transient",
        "study": "convergence / modes / reflection / speed studies",
    }
    for name, text in helps.items():
        sp = sub.add_parser(name, help=text, description=text)
        if name == "study":
            sp.add_argument("kind", choices=STUDIES, help="which study")
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
                        help="output folder (default: results/<case.name>)")
        sp.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE",
                        help="override a case key, e.g. --set mesh.refinement=2 (repeatable)")
    return p


def _split_petsc(argv: list[str]) -> tuple[list[str], list[str]]:
    if "--" in argv:
        k = argv.index("--")
        return argv[:k], argv[k + 1:]
    return argv, []


def _out_dir(args: argparse.Namespace, case: Case) -> Path:
    if args.out is not None:
        return args.out
    default = Path("results") / case["case.name"]
    return default / "transient" if args.command == "transient" else default


def _cmd_check(case: Case, rep: Reporter) -> int:
    from .mesh.layout import build_layout

    lay = build_layout(case)
    rep.info(f"case '{case['case.name']}' is valid (preset '{case['case.preset']}', "
             f"file {case.path or '<defaults>'})")
    rep.info(f"  track: {len(lay.sleeper_x)} sleepers, flexible rail "
             f"{case['track.rail_length']:g} m, {lay.rail_div} rail elements per bay")
    rep.info(f"  mesh: {len(lay.blocks)} structured blocks, refinement {case['mesh.refinement']:g}"
             + (f", from file {case['mesh.file']}" if case["mesh.file"] else ""))
    return 0


def _cmd_mesh(case: Case, out: Path, rep: Reporter) -> int:
    from .mesh.stage import format_report, run_mesh_stage

    def work():
        with rep.stage("mesh"):
            _, report = run_mesh_stage(case, out, rep)
        rep.info(format_report(report))
        rep.info("mesh timings: " + ", ".join(f"{k} {v:.2f} s"
                                                for k, v in report["timings"].items()))
        rep.info(f"wrote {out / 'mesh.xdmf'} (open in ParaView), {out / 'mesh.h5'}"
                 + ("" if case["mesh.file"] else f", {out / 'mesh.msh'}"))
        return report

    on_root(work, broadcast_result=False)
    return 0


def _cmd_modal(case: Case, out: Path, comm, rep: Reporter) -> dict:
    from .modal.stage import run_modal_stage

    return run_modal_stage(case, out, comm, rep)


def _cmd_mbs(case: Case, out: Path, comm, rep: Reporter) -> dict:
    from .mbs.stage import run_mbs_stage

    return run_mbs_stage(case, out, comm, rep)


def _reconstruct_options(case: Case, out: Path) -> dict:
    """Stride, window, precision, stress times and user probes from ``[output]`` (rank 0)."""
    import h5py
    import numpy as np

    mbs = out / "mbs.h5"
    stride = 1
    if mbs.exists() and case["output.dt"] > 0:
        with h5py.File(mbs, "r") as f:
            t = f["time"][:2]
        if t.size == 2:
            stride = max(1, int(round(case["output.dt"] / float(t[1] - t[0]))))
    w = case["output.window"]
    probes = np.asarray(case["output.probes"], dtype=float).reshape(-1, 3)
    return {"stride": stride, "window": tuple(w) if w else None,
            "float32": case["output.float32"], "stress_times": case["output.stress_times"],
            "correction_rates": case["output.static_correction_rates"],
            "user_probes": {f"user_{i + 1}": p for i, p in enumerate(probes)}}


def _cmd_reconstruct(case: Case, out: Path, comm, rep: Reporter) -> dict:
    from .reconstruct import run_reconstruct_stage

    opts = on_root(lambda: _reconstruct_options(case, out), comm)
    return run_reconstruct_stage(out / "modes.h5", out / "mbs.h5", out, comm, rep, **opts)


def _cmd_assess(case: Case, out: Path, comm, rep: Reporter) -> dict:
    from .assess.stage import run_assess_stage

    return run_assess_stage(case, out, comm, rep)


def run(argv: list[str] | None = None) -> int:
    """Parse arguments and run a command; returns the exit code (raises nothing for user errors)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    argv, petsc_options = _split_petsc(argv)
    args = _parser().parse_args(argv)
    comm = world()
    rep = Reporter(comm.rank)
    try:
        case = on_root(lambda: load_case(args.case, args.overrides))
        for note in case.notes:
            rep.info(f"note: {note}")
        out = _out_dir(args, case)
        if args.command in ("modal", "run", "transient"):
            from .petsc_env import init_petsc

            init_petsc(petsc_options)
        if args.command == "check":
            return _cmd_check(case, rep)
        if args.command == "mesh":
            return _cmd_mesh(case, out, rep)
        if args.command == "modal":
            _cmd_modal(case, out, comm, rep)
            rep.info("\n" + rep.timing_table())
            return 0
        single = {"mbs": _cmd_mbs, "reconstruct": _cmd_reconstruct, "assess": _cmd_assess}
        if args.command in single:
            single[args.command](case, out, comm, rep)
            rep.info("\n" + rep.timing_table())
            return 0
        if args.command == "transient":
            from .transient.stage import run_transient_stage

            _cmd_check(case, rep)
            run_transient_stage(case, out, comm, rep)
            summary = _cmd_assess(case, out, comm, rep)
            rep.info("\n" + rep.timing_table())
            failed = [k for k, v in summary["verdict"].items() if v is False]
            rep.info(f"transient complete: {len(summary['verdict'])} probes assessed, "
                     + (f"limits exceeded at {', '.join(failed)}" if failed
                        else "no limit exceeded"))
            return 0
        if args.command == "study":
            from .studies import run_study

            return run_study(args.kind, case, out, comm, rep, variants=args.variant,
                             merge_only=args.merge, prepare=args.prepare,
                             list_only=args.list, study_set=args.study_set,
                             petsc_options=petsc_options)
        # run: every stage in order; report the ones that do not exist yet
        _cmd_check(case, rep)
        _cmd_mesh(case, out, rep)
        _cmd_modal(case, out, comm, rep)
        _cmd_mbs(case, out, comm, rep)
        _cmd_reconstruct(case, out, comm, rep)
        summary = _cmd_assess(case, out, comm, rep)
        rep.info("\n" + rep.timing_table())
        verdict = summary["verdict"]
        failed = [k for k, v in verdict.items() if v is False]
        rep.info(f"pipeline complete: {len(verdict)} probes assessed, "
                 + (f"limits exceeded at {', '.join(failed)}" if failed
                    else "no limit exceeded"))
        return 0
    except UserError as exc:
        if comm.rank == 0:
            print(f"railvib {args.command}: error: {exc}", file=sys.stderr, flush=True)
        return exc.exit_code
    finally:
        if petsc_options and args.command not in ("modal", "run", "transient"):
            rep.info("PETSc options ignored by this command: " + " ".join(petsc_options))


def main() -> int:
    """Console-script entry point."""
    return run()
