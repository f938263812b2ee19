"""The merged report of a study: ``report.md``, ``report.json`` and ``figures/*.png``.

Written by rank 0 into ``<out>/<study>/`` from the finished variants (each file under a
temporary name, renamed when complete). ``report.json`` (schema
``railvib_hpc.study_report/1``)::

    study, case {name, file, loading (a case without a track only)}, settings {..},
    generated (UTC ISO time)
    variants [{name, parameter, status: finished|failed|pending|stale, wall_s, error}]
    complete (every variant finished), verdict {text, ok, ...}
    analysis {..}  (study-specific tables and numbers, see each study module)
    figures [file names]
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..io.atomic import atomic_file, write_text
from ..io.files import REPORT_JSON, REPORT_MD
from .common import jsonable

REPORT_FORMAT = "railvib_hpc.study_report/1"


def fmt(x: Any, digits: int = 4) -> str:
    """Compact number formatting for tables ('–' for None/NaN)."""
    if x is None:
        return "–"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}"
    if isinstance(x, float):
        if not math.isfinite(x):
            return "–"
        return f"{x:.{digits}g}"
    return str(x)


def pct(x: float | None, digits: int = 2) -> str:
    """A fraction as a percentage string ('–' for None)."""
    if x is None or not math.isfinite(x):
        return "–"
    return f"{100 * x:.{digits}f} %"


def md_table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A GitHub-flavoured markdown table."""
    def esc(c: str) -> str:
        return str(c).replace("|", "\\|")

    lines = ["| " + " | ".join(esc(h) for h in head) + " |",
             "|" + "|".join("---" for _ in head) + "|"]
    lines += ["| " + " | ".join(esc(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def transpose(head: Sequence[str], rows: Sequence[Sequence[str]], corner: str = "quantity"
              ) -> tuple[list[str], list[list[str]]]:
    """Swap rows and columns: the first column becomes the header (``corner`` first)."""
    new_head = [corner, *(str(r[0]) for r in rows)]
    new_rows = [[str(h), *(str(r[i]) for r in rows)] for i, h in enumerate(head) if i > 0]
    return new_head, new_rows


def text_table(head: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """A fixed-width table for the terminal."""
    cells = [list(map(str, head))] + [list(map(str, r)) for r in rows]
    widths = [max(len(r[i]) for r in cells) for i in range(len(head))]
    out = ["  ".join(c.ljust(w) for c, w in zip(cells[0], widths)),
           "  ".join("-" * w for w in widths)]
    out += ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in cells[1:]]
    return "\n".join(out)


def figure(**kwargs: Any):
    """A matplotlib Figure on an Agg canvas (no pyplot state; batch-safe)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(layout="constrained", **kwargs)
    FigureCanvasAgg(fig)
    return fig


def save(fig: Any, path: Path) -> Path:
    """Save a figure as PNG atomically; returns the path."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110)
    return path


def write_report(root: Path, kind: str, case_info: dict, settings: dict,
                 status: list[dict], analysis: dict, figures: list[Path]) -> dict[str, Path]:
    """Write ``report.md`` and ``report.json`` of a study.

    Parameters
    ----------
    root
        ``<out>/<study>``.
    kind
        The study.
    case_info
        ``{"name", "file"}`` of the case, and for a case without a track ``loading``: the
        sentence saying what loads it and which vehicle quantities are absent (the
        report's **Loading** line).
    settings
        The study settings.
    status
        One entry per variant: ``name``, ``parameter``, ``status``, ``wall_s``, ``error``.
    analysis
        From the study module: ``title``, ``verdict`` (``text``, ``ok``), ``tables``
        (list of ``{title, head, rows, note}``), ``sections`` (list of ``[title,
        markdown]``) and any data.
    figures
        PNG files (in ``root/figures``).

    Returns
    -------
    dict
        ``{"markdown": path, "json": path}``.
    """
    finished = sum(s["status"] == "finished" for s in status)
    complete = finished == len(status)
    now = _dt.datetime.now(_dt.timezone.utc).replace(microsecond=0).isoformat()
    lines = [f"# {analysis.get('title', kind)}", "",
             f"Case `{case_info['name']}` ({case_info['file']}), generated {now}.", "",
             f"**Verdict:** {analysis['verdict']['text']}", ""]
    if case_info.get("loading"):
        lines += [f"**Loading:** {case_info['loading']}", ""]
    if not complete:
        lines += [f"**Incomplete:** {finished} of {len(status)} variants finished; the "
                  "verdict uses the finished ones only.", ""]
    lines += ["## Settings", "",
              md_table(["setting", "value"], [[k, f"`{v}`"] for k, v in settings.items()]),
              "", "## Variants", "",
              md_table(["variant", "parameter", "status", "wall [s]", "note"],
                       [[s["name"], ", ".join(f"{k} = {v}" for k, v in s["parameter"].items()),
                         s["status"], fmt(s.get("wall_s"), 3),
                         (s.get("error") or "").splitlines()[0][:160] if s.get("error")
                         else ("reused" if s.get("reused") else "")]
                        for s in status]), ""]
    for t in analysis.get("tables", []):
        lines += [f"## {t['title']}", "", md_table(t["head"], t["rows"]), ""]
        if t.get("note"):
            lines += [t["note"], ""]
    for title, text in analysis.get("sections", []):
        lines += [f"## {title}", "", text, ""]
    if figures:
        lines += ["## Figures", ""]
        lines += [f"![{p.stem}](figures/{p.name})" for p in figures]
        lines.append("")
    md = root / REPORT_MD
    write_text(md, "\n".join(lines))
    payload = {"schema": REPORT_FORMAT, "study": kind, "case": case_info,
               "settings": settings, "generated": now, "variants": status,
               "complete": complete, "verdict": analysis["verdict"],
               "analysis": {k: v for k, v in analysis.items()
                            if k not in ("verdict", "sections", "title", "tables")},
               "tables": analysis.get("tables", []),
               "figures": [f"figures/{p.name}" for p in figures]}
    js = root / REPORT_JSON
    write_text(js, json.dumps(jsonable(payload), indent=1))
    return {"markdown": md, "json": js}
