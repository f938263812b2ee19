"""Cross-key checks of the solution: the band-sliced eigensolve, damping and the
transient stage, the vehicles, their speeds and the multibody settings.
"""

from __future__ import annotations

from typing import Any

from ..schema import IMPLICIT_GROUPS, PARTS, CaseView
from ..site import ground_rayleigh_speeds
from ..time_engines import needs_lumped_mass


def _check_bands(case: CaseView) -> list[tuple[str, Any, str]]:
    """Cross-key checks of the band-sliced eigensolve settings."""
    out: list[tuple[str, Any, str]] = []
    md = case["modal"]
    edges = list(md["bands"])
    # (modal.f_max = 0: the rule of Param.applies refuses the bands)
    if edges and md["f_max"] > 0 and (any(not 0 < e < md["f_max"] for e in edges) or
                                      any(b <= a for a, b in zip(edges, edges[1:]))):
        out.append(("modal.bands", edges, f"must be strictly ascending inside (0, "
                                          f"modal.f_max = {md['f_max']!r})"))
    if (md["bands"] or md["band_only"] or md["band_groups"] > 1) and \
            md["method"] != "block_lanczos":
        out.append(("modal.method", md["method"], "band settings need 'block_lanczos'"))
    return out


def _boundary_kind_problems(case: CaseView) -> list[tuple[str, Any, str]]:
    """The ``[boundary]`` checks of the kinds on the faces, in registry order
    (:meth:`~railvib_hpc.model.boundary_kind.BoundaryKind.section_problems`: a caughey or
    pml layer's thickness, the pml's target reflection)."""
    from ..boundary_registry import BOUNDARY_KINDS, boundary_kind

    faces = ("x_min", "x_max", "y_min", "y_max", "base")
    on = {name: [f for f in faces if case[f"boundary.{f}"] == name] for name in BOUNDARY_KINDS}
    return [p for name, where in on.items() if where
            for p in boundary_kind(name).section_problems(case["boundary"], where)]


def _check_dynamics(case: CaseView) -> list[tuple[str, Any, str]]:
    """Cross-key checks of [damping] and [transient]."""
    out: list[tuple[str, Any, str]] = []
    d, tr = case["damping"], case["transient"]
    out.extend(_boundary_kind_problems(case))
    if not d["f1"] < d["f2"]:
        out.append(("damping.f2", d["f2"], f"must be greater than damping.f1 = {d['f1']:g} Hz "
                    "(the two frequencies of the Rayleigh damping)"))
    odt = case["output.dt"]
    if tr["dt"] > 0 and odt > 0:
        ratio = odt / tr["dt"]
        if ratio < 1.0 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
            out.append(("transient.dt", tr["dt"],
                        f"must divide output.dt = {odt:g} s into whole steps (or be 0: "
                        "automatic)"))
    if tr["engine"] in needs_lumped_mass() and not case["modal.lumped_mass"]:
        out.append(("transient.engine", tr["engine"],
                    "needs a diagonal mass: set modal.lumped_mass = true (or use "
                    "transient.engine = \"direct\")"))
    unknown = [p for p in tr["implicit_parts"] if p not in IMPLICIT_GROUPS and p not in PARTS]
    if unknown:
        out.append(("transient.implicit_parts", unknown[0],
                    "must be a part name or one of the groups "
                    + ", ".join(IMPLICIT_GROUPS) + " (parts: " + ", ".join(PARTS) + ")"))
    return out


def _vehicle_problems(v: dict[str, Any], gauge: float, section: str
                      ) -> list[tuple[str, Any, str]]:
    """Cross-key checks of one vehicle's keys (``[vehicle]`` or the second train's)."""
    out: list[tuple[str, Any, str]] = []
    if any(o > 0 for o in v["axle_offsets"]) or not v["axle_offsets"]:
        out.append((f"{section}.axle_offsets", v["axle_offsets"],
                    "must be a non-empty list of offsets <= 0 (behind the leading axle)"))
    if v["contact_span"] >= 2.0 * gauge:
        out.append((f"{section}.contact_span", v["contact_span"],
                    f"must be close to the track gauge ({gauge:g} m)"))
    if v["wheelbase"] >= v["bogie_spacing"]:
        out.append((f"{section}.wheelbase", v["wheelbase"],
                    f"must be smaller than {section}.bogie_spacing = {v['bogie_spacing']:g} m"))
    if v["bogie_spacing"] + v["wheelbase"] >= v["car_length"]:
        out.append((f"{section}.car_length", v["car_length"],
                    "must exceed bogie_spacing + wheelbase (the wheels of successive cars "
                    "must not overlap)"))
    return out


def _speed_problems(case: CaseView) -> list[tuple[str, Any, str]]:
    """A train at or above the ground's lowest Rayleigh speed, unless vehicle.supercritical
    accepts it."""
    if case["vehicle.supercritical"]:
        return []
    try:
        speeds = ground_rayleigh_speeds(case)
    except (KeyError, ValueError, ZeroDivisionError):
        return []                        # (bad materials are reported by their own checks)
    part, c_r = min(speeds.items(), key=lambda kv: kv[1])
    trains = [("vehicle.speed", case["vehicle.speed"]) if case["track.count"]
              else ("load.speed", case["load.speed"])]           # the surface load's
    if case["track.count"] == 2 and case["train2.speed"] > 0:
        trains.append(("train2.speed", case["train2.speed"]))
    return [(key, v, f"is at or above the ground's Rayleigh speed c_R = {c_r:.1f} m/s "
             f"({part}; " + ", ".join(f"{k} {c:.1f}" for k, c in speeds.items())
             + " m/s): the track's critical speed, where the response grows and forms a "
             f"Mach cone; allowed: < {c_r:.1f} m/s, or set vehicle.supercritical = true "
             "to run it")
            for key, v in trains if v >= c_r]


def _check_mbs(case: CaseView) -> list[tuple[str, Any, str]]:
    """Cross-key checks of [vehicle], [irregularity] and [mbs]."""
    out: list[tuple[str, Any, str]] = []
    v, irr, mbs = case["vehicle"], case["irregularity"], case["mbs"]
    out.extend(_vehicle_problems(v, case["track.gauge"], "vehicle"))
    out.extend(_speed_problems(case))
    if v["x_end"] and v["x_end"] <= v["x_start"]:
        out.append(("vehicle.x_end", v["x_end"],
                    f"must be 0 (end of the rigid exit rail) or > vehicle.x_start = "
                    f"{v['x_start']:g} m"))
    if irr["type"] == "file":
        if not irr["file"]:
            out.append(("irregularity.file", "", "irregularity.type = 'file' needs a file"))
        elif not case.resolve(irr["file"]).is_file():
            out.append(("irregularity.file", irr["file"],
                        f"file not found (looked for {case.resolve(irr['file'])})"))
    classes = {"fra": "123456", "iso8608": "ABCDEFGH"}
    if irr["type"] in classes and irr["track_class"] not in classes[irr["type"]]:
        out.append(("irregularity.track_class", irr["track_class"],
                    f"{irr['type']} classes are " + ", ".join(classes[irr["type"]])))
    if irr["wavelength_min"] >= irr["wavelength_max"]:
        out.append(("irregularity.wavelength_min", irr["wavelength_min"],
                    f"must be < irregularity.wavelength_max = {irr['wavelength_max']:g} m"))
    if any(w < 0 or not float(w).is_integer() for w in irr["flat_wheels"]):
        out.append(("irregularity.flat_wheels", irr["flat_wheels"],
                    "must be wheel indices (integers >= 0)"))
    o = case["output"]
    if o["window"] and (len(o["window"]) != 2 or o["window"][0] >= o["window"][1]
                        or o["window"][0] < 0):
        out.append(("output.window", o["window"], "must be empty or [t0, t1] with 0 <= t0 < t1"))
    if len(o["probes"]) % 3:
        out.append(("output.probes", o["probes"],
                    "must be a flat list of x, y, z triples (length a multiple of 3)"))
    elif o["probe_roles"] and len(o["probe_roles"]) != len(o["probes"]) // 3:
        out.append(("output.probe_roles", o["probe_roles"],
                    f"must be empty or give one role per point of output.probes "
                    f"({len(o['probes']) // 3})"))
    if any(t < 0 for t in o["stress_times"]):
        out.append(("output.stress_times", o["stress_times"], "times must be >= 0"))
    modes, ratios = mbs["damping_modes"], mbs["damping_ratios"]
    if len(modes) != len(ratios):
        out.append(("mbs.damping_ratios", ratios,
                    f"needs one ratio per entry of mbs.damping_modes ({len(modes)})"))
    if any(k < 1 or not float(k).is_integer() for k in modes):
        out.append(("mbs.damping_modes", modes, "must be mode numbers (integers >= 1)"))
    if any(not 0.0 <= r < 1.0 for r in ratios):
        out.append(("mbs.damping_ratios", ratios, "must satisfy 0 <= ratio < 1"))
    return out
