"""Speed sweep: peak building response and contact force against the running speed.

The modes are the case's, computed once in ``<out>/speed/model`` (with ``static.h5`` when
the case asks for the static correction); every variant ``v<speed>`` links to them and
runs only the MBS at ``vehicle.speed`` and the probe histories. ``solver = direct`` runs
every speed with the full-order time integration (``railvib transient``) instead. The
automatic MBS step keeps 40 steps per rail element passage, so every speed costs about the
same.

A case without a track (``track.count = 0``, ``solver = direct`` only) varies the speed of
its moving load, ``load.speed`` (below the ground's Rayleigh speed unless
``vehicle.supercritical``); its table, verdict and figure leave out the vehicle's contact
force, dynamic factor and rail deflection (there is none).

Verdict: the speed with the largest building acceleration, how the peak contact force
grows with speed, and whether every speed passes the assessment of ``[assessment]``
(largest utilisation of the binding standards at the study's probes); with speeds not
finished it says how many and claims nothing about them (``ok`` is then None unless a
finished speed fails).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..config import Case
from .common import StudyPlan, Variant, all_with_contact_force, response_quantities
from .protocol import Study
from .report import figure, fmt, save, transpose

TITLE = "Speed sweep"


def speed_key(case: Case) -> str:
    """The key a speed variant sets: ``vehicle.speed``, or ``load.speed`` for a case
    without a track (``track.count = 0``: the moving load of ``[load]``)."""
    return "load.speed" if case["track.count"] == 0 else "vehicle.speed"


def plan(case: Case, settings: dict[str, Any], root: Path | None = None) -> StudyPlan:
    """A shared model (the case's modes); one MBS variant per speed. With ``solver =
    direct`` every speed is a full-order time integration of its own (no shared model);
    a case without a track varies the speed of its moving load (:func:`speed_key`)."""
    direct = settings.get("solver", "modal") == "direct"
    key = speed_key(case)
    variants = tuple(Variant(name=f"v{s:g}", overrides=(f"{key}={s!r}",),
                             parameter={"speed": s}, shared=not direct)
                     for s in settings["speeds"])
    return StudyPlan("speed", variants, shared_overrides=None if direct else ())


def analyse(plan_: StudyPlan, results: dict[str, dict], settings: dict[str, Any]) -> dict:
    """Table per speed, the critical speed and the pass/fail summary."""
    done = [v for v in plan_.variants if v.name in results]
    if not done:
        return {"title": TITLE, "verdict": {"text": "no speed finished", "ok": None},
                "tables": [], "rows": []}
    probes = settings["probes"]
    data = []
    for v in done:
        r = results[v.name]
        q = response_quantities(r, probes)
        ass = r["assessment"]
        utils = [a["max_utilisation"] for a in ass.values() if a["max_utilisation"] is not None]
        passed = [a["passed"] for a in ass.values()]
        gov = max(ass, key=lambda p: ass[p]["max_utilisation"] or 0.0) if ass else None
        mbs = r["mbs"] or {}                         # None: no vehicle (no track)
        data.append({"variant": v.name, "speed": v.parameter["speed"], "quantities": q,
                     "dynamic_factor": mbs.get("dynamic_factor"),
                     "min_contact_force": mbs.get("min_contact_force"),
                     "max_rail_deflection": mbs.get("max_rail_deflection"),
                     "loss_of_contact_steps": mbs.get("loss_of_contact_steps"),
                     "max_utilisation": max(utils) if utils else None, "governing_probe": gov,
                     "passed": (False if False in passed else
                                None if None in passed or not passed else True),
                     "duration": r["duration"], "wall_s": r["timings"]["total"]})
    acc = [k for k in data[0]["quantities"] if k != "peak contact force"]
    vehicle = all_with_contact_force(data)    # the contact forces of a train, if any
    head = ["variant", "speed [m/s]", *(VEHICLE_HEAD if vehicle else ()), *acc,
            "max utilisation", "assessment", "record [s]", "wall [s]"]
    rows = [[d["variant"], fmt(d["speed"]), *(_vehicle_cells(d) if vehicle else ()),
             *(fmt(d["quantities"][k]) for k in acc), fmt(d["max_utilisation"], 3),
             {True: "pass", False: "FAIL", None: "undetermined"}[d["passed"]],
             fmt(d["duration"], 3), fmt(d["wall_s"], 3)] for d in data]
    verdict = _verdict(data, acc, len(plan_.variants))
    note = ("Accelerations in m/s² (a_z vertical, |a| total peak). max utilisation: largest "
            "value/limit of the binding standards over the probes (≤ 1 passes).")
    if not vehicle:
        note += (" No vehicle (a case without a track): the speed is the moving load's "
                 "(load.speed); no contact force, dynamic factor or rail deflection.")
    return {"title": TITLE, "verdict": verdict, "rows": data,
            "tables": [{"title": "Responses per speed",
                        **dict(zip(("head", "rows"), transpose(head, rows))),
                        "note": note}]}


#: The columns of a vehicle's metrics (left out without a track).
VEHICLE_HEAD = ("peak contact force [N]", "dynamic factor", "min contact force [N]",
                "rail deflection [mm]")


def _vehicle_cells(d: dict) -> list[str]:
    """The :data:`VEHICLE_HEAD` cells of one speed."""
    return [fmt(d["quantities"]["peak contact force"]), fmt(d["dynamic_factor"]),
            fmt(d["min_contact_force"]), fmt(1e3 * d["max_rail_deflection"])]


def _verdict(data: list, acc: list[str], planned: int | None = None) -> dict:
    """The verdict from the finished speeds ``data`` of ``planned`` (never a claim about
    every speed when some did not finish)."""
    planned = len(data) if planned is None else planned
    total = [k for k in acc if k.endswith("|a|")] or acc

    def building_peak(d: dict) -> tuple[float, str]:
        k = max(total, key=lambda k: d["quantities"][k])
        return d["quantities"][k], k

    crit = max(data, key=lambda d: building_peak(d)[0])
    a_crit, key = building_peak(crit)
    lo = data[0]
    vehicle = all_with_contact_force(data)
    fmax = max(data, key=lambda d: d["quantities"]["peak contact force"]) if vehicle else None
    fails = [d["speed"] for d in data if d["passed"] is False]
    undet = [d["speed"] for d in data if d["passed"] is None]
    umax = max(data, key=lambda d: d["max_utilisation"] or 0.0)
    text = (f"largest building acceleration at {crit['speed']:g} m/s ({key} = {a_crit:.3g} "
            f"m/s², {a_crit / max(lo['quantities'][key], 1e-300):.2f}x its value at "
            f"{lo['speed']:g} m/s); ")
    if fmax is not None:
        text += (f"largest contact force {fmax['quantities']['peak contact force']:.0f} N "
                 f"at {fmax['speed']:g} m/s (dynamic factor {fmax['dynamic_factor']:.3f}); ")
    else:
        text += "no vehicle (the moving load of [load]: no contact force); "
    if fails:
        text += "limits EXCEEDED at " + ", ".join(f"{s:g}" for s in fails) + " m/s"
    elif undet:
        text += ("no limit exceeded, undetermined at " + ", ".join(f"{s:g}" for s in undet)
                 + " m/s")
    elif len(data) < planned:
        text += f"every finished speed ({len(data)} of {planned}) passes every standard"
    else:
        text += "every speed passes every standard"
    text += (f" (largest utilisation {umax['max_utilisation'] or 0.0:.3f} at "
             f"{umax['speed']:g} m/s, {umax['governing_probe']})")
    ok = False if fails else (None if len(data) < planned else True)
    return {"text": text, "ok": ok, "critical_speed": crit["speed"],
            "critical_quantity": key, "critical_value": a_crit,
            "max_contact_force_speed": None if fmax is None else fmax["speed"],
            "failing_speeds": fails,
            "max_utilisation": umax["max_utilisation"], "max_utilisation_speed": umax["speed"]}


def figures(analysis: dict, settings: dict[str, Any], fig_dir: Path,
            results: dict[str, dict] | None = None) -> list[Path]:
    """Building peaks, contact force and utilisation against speed."""
    data = analysis.get("rows") or []
    if not data:
        return []
    speeds = [d["speed"] for d in data]
    vehicle = all_with_contact_force(data)     # no contact-force panel without one
    fig = figure(figsize=(13 if vehicle else 9, 4.2))
    axes = list(fig.subplots(1, 3 if vehicle else 2))
    a1, a3 = axes[0], axes[-1]
    for p in settings["probes"]:
        a1.plot(speeds, [d["quantities"][f"{p} |a|"] for d in data], "o-", ms=4, label=p)
    a1.set_ylabel("peak total acceleration [m/s²]")
    if vehicle:
        a2 = axes[1]
        a2.plot(speeds, [d["quantities"]["peak contact force"] / 1e3 for d in data], "o-",
                ms=4, label="peak")
        a2.plot(speeds, [d["min_contact_force"] / 1e3 for d in data], "s--", ms=4,
                label="min")
        a2.set_ylabel("contact force [kN]")
        a2.legend(fontsize=7)
    a3.plot(speeds, [d["max_utilisation"] or 0.0 for d in data], "o-", ms=4)
    a3.axhline(1.0, color="r", lw=0.8)
    a3.set_ylabel("largest utilisation (≤ 1 passes)")
    for ax in axes:
        ax.set_xlabel("speed [m/s]" if vehicle else "load speed [m/s]")
        ax.grid(alpha=0.3)
    a1.legend(fontsize=7)
    return [save(fig, fig_dir / "speed.png")]


STUDY = Study(
    name="speed",
    help=("speed sweep: peak building response and contact force against the running "
          "speed"),
    title=TITLE, plan=plan, analyse=analyse, figures=figures,
    sorted_settings=("speeds",),
)
