"""Trench insertion loss against depth over the Rayleigh wavelength (issue 28, item 7).

Reads the ``report.json`` of one or more ``railvib study mitigation`` runs (e.g. of
``jobs/trench_deep.toml`` on its deep domain with absorbing faces, and of the same study on
the thesis faces) and prints, for every trench measure and every one-third-octave band up to
the study's resolved band (``transient.f_max`` with ``solver = "direct"``), the insertion
loss [dB] with the trench depth ``D`` over the Rayleigh wavelength ``lambda_R = c_R / f`` of
the soil the trench is cut in (the ground's top soil: ``railvib_hpc.site``'s Rayleigh
speeds), averaged over the ground probes behind the trench and, separately, over the
building probes::

    python bench/trench_depth_table.py /tmp/trench/deep/mitigation /tmp/trench/shallow/mitigation

The literature's screening rule (Woods 1968; Ahmad & Al-Hussaini 1991): an open trench
screens little below ``D / lambda_R ~ 0.1`` and 10 dB or more from ``D / lambda_R ~
0.6-1`` on. A fixed base just under the trench (the thesis domain's 4.8 m) traps the
waves under it and exaggerates the screening; absorbing faces on a deep domain do not.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from railvib_hpc.config import Case  # noqa: E402
from railvib_hpc.site import ground_rayleigh_speeds  # noqa: E402

#: Probe names on the ground (the free field behind the trench); the rest are the building's.
GROUND_PREFIX = "ground_"


def _overrides(row: dict) -> dict[str, str]:
    out = {}
    for item in row["overrides"]:
        key, _, value = item.partition("=")
        out[key.strip()] = value.strip()
    return out


def _top_soil_rayleigh_speed(report: dict) -> tuple[str, float]:
    """The Rayleigh speed of the soil at the ground (the first layer, or the subgrade) of
    the study's case file (``--set`` overrides of the soil are not in ``report.json``)."""
    speeds = ground_rayleigh_speeds(Case.from_file(report["case"]["file"]))
    name = "soil_layer_1" if "soil_layer_1" in speeds else "subgrade"
    return name, speeds.get(name, min(speeds.values()))


def table(folder: Path) -> list[str]:
    """The printed table of one study folder (its ``report.json``)."""
    report = json.loads((folder / "report.json").read_text())
    rows = report["analysis"]["rows"]
    soil, c_r = _top_soil_rayleigh_speed(report)
    lines = [f"# {folder}: c_R = {c_r:.1f} m/s ({soil}); "
             f"{len(rows)} measures; complete: {report['complete']}"]
    # (the study keeps only the bands both variants resolve: transient.f_max, direct)
    bands = sorted({float(f) for r in rows for d in r["il_band_db"].values() for f in d})
    head = f"{'measure':<20} {'D [m]':>6} {'probes':>8} " + " ".join(
        f"{f:>7g}" for f in bands)
    lines += [head, f"{'':<20} {'':>6} {'D/lR':>8} " + " ".join(
        f"{'':>7}" for _ in bands)]
    for r in sorted(rows, key=lambda r: (_overrides(r).get("trench.type", ""),
                                         float(_overrides(r).get("trench.depth", 0)))):
        ov = _overrides(r)
        if ov.get("trench.type", "none") == "none":
            continue
        depth = float(ov["trench.depth"])
        label = f"{r['measure'][:20]:<20}"
        ratio = " ".join(f"{depth * f / c_r:>7.2f}" for f in bands)
        lines.append(f"{label} {depth:>6.1f} {'D/lR':>8} {ratio}")
        for group, pick in (("ground", True), ("building", False)):
            vals = []
            for f in bands:
                xs = [d[str(f)] for p, d in r["il_band_db"].items()
                      if p.startswith(GROUND_PREFIX) == pick and str(f) in d]
                vals.append(f"{np.mean(xs):>7.1f}" if xs else f"{'-':>7}")
            lines.append(f"{'':<20} {'':>6} {group:>8} " + " ".join(vals))
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folders", nargs="+", type=Path,
                    help="study folders holding report.json (<out>/mitigation)")
    args = ap.parse_args(argv)
    for folder in args.folders:
        print("\n".join(table(folder)))
        print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
