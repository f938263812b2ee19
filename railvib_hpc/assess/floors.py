"""The assessment per floor: every building probe's verdicts gathered by storey.

A floor is the set of ``floor`` probes of one slab (``slab<k>`` and ``slab<k>_x<i>y<j>_mid``
/ ``_corner``, :mod:`railvib_hpc.mesh.building`); the ``wall`` and ``foundation`` probes
form the floor ``basement``; ``floor`` probes of the user (``output.probes`` with
``output.probe_roles``) that are not named after a slab form ``other floor probes``. Per
floor and standard: the largest utilisation, the probe where it occurs and whether every
probe passes. Ground probes are not part of the building and are left out.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from ..mesh.building import storey_of_probe

#: Label of the floor of the wall and foundation probes.
BASEMENT = "basement"
#: Label of user floor probes not named after a slab.
OTHER = "other floor probes"


def floor_of(name: str, role: str) -> str | None:
    """The floor label of a probe (None: not a building probe)."""
    if role == "floor":
        k = storey_of_probe(name)
        return f"floor {k}" if k is not None else OTHER
    if role in ("wall", "foundation"):
        return BASEMENT
    return None


def floor_summary(results: Mapping[str, Mapping[str, Any]], roles: Mapping[str, str]
                  ) -> dict[str, dict[str, Any]]:
    """Per floor: its probes and, per standard, the largest utilisation and the verdict.

    Parameters
    ----------
    results
        ``assess_probe`` results per probe name.
    roles
        The role of every probe.

    Returns
    -------
    dict
        Floor label -> ``{"probes": [...], "passed": bool | None, "standards": {standard:
        {"utilisation", "governing_probe", "passed"}}}``, the basement first, then the floors
        bottom up.
    """
    floors: dict[str, list[str]] = {}
    for name in results:
        label = floor_of(name, roles.get(name, ""))
        if label is not None:
            floors.setdefault(label, []).append(name)

    def order(label: str) -> tuple[int, int]:
        if label == BASEMENT:
            return (0, 0)
        if label == OTHER:
            return (2, 0)
        return (1, int(label.split()[1]))

    out = {}
    for label in sorted(floors, key=order):
        names = floors[label]
        standards: dict[str, dict[str, Any]] = {}
        for name in names:
            for std, block in results[name]["standards"].items():
                s = standards.setdefault(std, {"utilisation": None, "governing_probe": None,
                                               "passed": True})
                u = block.get("utilisation")
                if u is not None and (s["utilisation"] is None or u > s["utilisation"]):
                    s["utilisation"], s["governing_probe"] = u, name
                if block.get("passed") is False:
                    s["passed"] = False
        verdicts = [results[n].get("passed") for n in names]
        passed = None if all(v is None for v in verdicts) else all(v is not False for v in verdicts)
        out[label] = {"probes": names, "passed": passed, "standards": standards}
    return out


def format_floor_table(floors: Mapping[str, Mapping[str, Any]]) -> str:
    """Fixed-width table: per floor and standard the verdict, the largest utilisation and
    its probe."""
    if not floors:
        return "no building probes"
    stds = sorted({s for f in floors.values() for s in f["standards"]})
    rows = [["floor", "probes", *stds, "overall"]]
    for label, f in floors.items():
        row = [label, str(len(f["probes"]))]
        for s in stds:
            b = f["standards"].get(s)
            if b is None:
                row.append("-")
                continue
            verdict = "pass" if b["passed"] else "FAIL"
            u = b["utilisation"]
            row.append(verdict if u is None else f"{verdict} {u:.3f} ({b['governing_probe']})")
        row.append({True: "pass", False: "FAIL", None: "-"}[f["passed"]])
        rows.append(row)
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append("cells: verdict, largest utilisation on the floor and the probe where it occurs")
    return "\n".join(lines)
