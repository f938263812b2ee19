"""A new study in one module: ``example`` sweeps the subgrade's Young's modulus and compares
its wave speeds with a limit (tests/studies/test_example_study.py).

Its declaration is all a study needs: its name and help line, its settings (its own,
outside the case schema), its variants, its own computation of a variant (the subgrade's
P- and S-wave speeds, no stage), its analysis with the verdict, and its figure. Registered
with one line (``railvib_hpc.studies.registry.STUDIES["example"] = "example_study"``) it
runs from the command line (``railvib study example CASE``: its name among the choices,
its help line in the help) and from the Python API (``rv.run_study("example", ...)``),
through the same runner as the package's studies: a folder and a lock per variant, its
``result.json`` (a rerun skips a finished variant), ``--list``, the merged report and the
verdict.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from railvib_hpc.parallel import on_root
from railvib_hpc.schema import Param
from railvib_hpc.studies.common import StudyPlan, Variant
from railvib_hpc.studies.protocol import Study
from railvib_hpc.studies.report import figure, fmt, save

TITLE = "Example: the subgrade's wave speeds against its stiffness"

#: Its settings, with their defaults (checked by the case schema's engine, as a table's).
SETTINGS = {
    "moduli": Param([1.0e8, 4.0e8], "floats", "Pa",
                    "the subgrade's Young's moduli, one variant each", "pos", unique=True),
    "max_shear_speed": Param(300.0, "float", "m/s",
                             "the verdict: every shear-wave speed at most this", "pos"),
}


def plan(case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """One variant per modulus: ``materials.subgrade.E``."""
    return StudyPlan("example", tuple(
        Variant(name=f"E{e:g}", overrides=(f"materials.subgrade.E={e!r}",),
                parameter={"E": e}) for e in settings["moduli"]))


def variant(plan_: StudyPlan, v: Variant, case, runner, settings: dict[str, Any]) -> dict:
    """The variant case's subgrade wave speeds (every rank: rank 0's)."""
    from railvib_hpc.assess.waves import wave_speeds
    from railvib_hpc.problem import Problem

    c_p, c_s = on_root(lambda: wave_speeds(Problem.from_case(case)), runner.comm)
    return {"wave_speeds": {"c_P": c_p, "c_S": c_s}}


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """A row per finished modulus and the verdict: every c_S at most the limit."""
    limit = settings["max_shear_speed"]
    rows = [{"variant": v.name, "E": v.parameter["E"], **results[v.name]["wave_speeds"]}
            for v in plan_.variants if v.name in results]
    if not rows:
        return {"title": TITLE, "verdict": {"text": "no modulus finished", "ok": None},
                "tables": [], "rows": []}
    fast = [r for r in rows if r["c_S"] > limit]
    fastest = max(rows, key=lambda r: r["c_S"])
    text = (f"shear-wave speed up to {fastest['c_S']:.1f} m/s (E = {fastest['E']:g} Pa); "
            + (f"above {limit:g} m/s at {', '.join(r['variant'] for r in fast)}" if fast
               else f"every one at most {limit:g} m/s"))
    return {"title": TITLE, "rows": rows,
            "verdict": {"text": text, "ok": not fast, "fastest": fastest["variant"]},
            "tables": [{"title": "Wave speeds per modulus",
                        "head": ["variant", "E [Pa]", "c_P [m/s]", "c_S [m/s]"],
                        "rows": [[r["variant"], fmt(r["E"]), fmt(r["c_P"]), fmt(r["c_S"])]
                                 for r in rows]}]}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """c_S against E."""
    rows = analysis.get("rows") or []
    if not rows:
        return []
    fig = figure(figsize=(5, 3.5))
    ax = fig.subplots()
    ax.plot([r["E"] for r in rows], [r["c_S"] for r in rows], "o-")
    ax.axhline(settings["max_shear_speed"], color="r", lw=0.8)
    ax.set_xlabel("subgrade E [Pa]")
    ax.set_ylabel("c_S [m/s]")
    return [save(fig, fig_dir / "example.png")]


STUDY = Study(name="example", help="the subgrade's wave speeds against its Young's modulus",
              title=TITLE, plan=plan, analyse=analyse, figures=figures, settings=SETTINGS,
              sorted_settings=("moduli",), variant=variant)
