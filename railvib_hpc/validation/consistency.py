"""The whole case checked for consistency (:func:`check_consistency`: the geometry's
order, then every cross-key check), the studies' tables (:func:`check_studies`) and the
refusals of a command (:func:`command_problems`).
"""

from __future__ import annotations

import importlib
from typing import Any

from ..schema import CaseView
from ..uncertain_inputs import check_uncertainty
from .dynamics import _check_bands, _check_dynamics, _check_mbs
from .features import feature_key_problems
from .layout import (
    _check_building,
    _check_interfaces,
    _check_line_points,
    _check_measures,
    _check_soil,
)
from .track import (
    _check_embankment,
    _check_static_start,
    _check_surface_load,
    _check_track_ends,
    _check_tracks,
)
from .values import _close


def check_consistency(case: CaseView) -> list[tuple[str, Any, str]]:
    """Geometric and cross-key checks; returns the list of problems."""
    g, t, b = case["geometry"], case["track"], case["building"]
    out: list[tuple[str, Any, str]] = []

    def order(keys: list[str], values: list[float], what: str) -> None:
        for (k0, v0), (k1, v1) in zip(zip(keys, values), zip(keys[1:], values[1:])):
            if not v0 < v1:
                out.append((f"geometry.{k1}", v1, f"must be greater than {k0} = {v0} ({what})"))

    if b["present"]:
        order(["x0", "x1", "x2", "x3", "x4"], [g[k] for k in ("x0", "x1", "x2", "x3", "x4")],
              "X0 < X1 < X2 < X3 < X4")
        order(["ys4", "ys3", "ys2", "ys1"], [g[k] for k in ("ys4", "ys3", "ys2", "ys1")],
              "YS4 < YS3 < YS2 < YS1 < 0 < YS0")
    else:                          # no building: its lines do not apply
        order(["x0", "x1", "x4"], [g[k] for k in ("x0", "x1", "x4")], "X0 < X1 < X4")
        order(["ys4", "ys1"], [g[k] for k in ("ys4", "ys1")], "YS4 < YS1 < 0 < YS0")
    if not g["ys1"] < 0:
        out.append(("geometry.ys1", g["ys1"], "must be < 0 (embankment toe on the building side)"))
    if not g["ys0"] > -g["ys1"]:
        out.append(("geometry.ys0", g["ys0"],
                    f"must be > |YS1| = {-g['ys1']} (soil must extend beyond the embankment)"))
    order(["z0", "z1", "z2", "z3", "z4"], [g[k] for k in ("z0", "z1", "z2", "z3", "z4")],
          "Z0 < Z1 < Z2 < Z3 < Z4")
    if out:
        return out
    out.extend(feature_key_problems(case))

    # track
    if not _close(g["x1"] - g["x0"], t["rigid_length"]):
        out.append(("track.rigid_length", t["rigid_length"],
                    f"must equal X1 - X0 = {g['x1'] - g['x0']:g} m"))
    if not _close(g["x4"] - g["x1"], t["rail_length"]):
        out.append(("track.rail_length", t["rail_length"],
                    f"must equal geometry.x4 - x1 = {g['x4'] - g['x1']:g} m (the soil spans "
                    "the flexible rail): give one of track.rail_length and geometry.x4, the "
                    "other follows"))
    nbays = t["rail_length"] / t["sleeper_spacing"]
    if abs(nbays - round(nbays)) > 1e-6:
        out.append(("track.sleeper_spacing", t["sleeper_spacing"],
                    f"must divide the flexible rail length {t['rail_length']:g} m into whole bays"))
    elif t["n_sleepers"] != round(nbays) + 1:
        out.append(("track.n_sleepers", t["n_sleepers"],
                    f"must be rail_length / sleeper_spacing + 1 = {round(nbays) + 1} (it is "
                    "derived: leave it out)"))
    half_sleeper = t["sleeper_length"] / 2
    if not t["gauge"] / 2 < half_sleeper:
        out.append(("track.gauge", t["gauge"],
                    f"the rails must sit on the sleepers: gauge/2 < sleeper_length/2 = "
                    f"{half_sleeper:g} m"))
    if not half_sleeper < g["ballast_top_half_width"]:
        out.append(("track.sleeper_length", t["sleeper_length"],
                    f"sleepers must lie on the ballast crest: length/2 < "
                    f"geometry.ballast_top_half_width = {g['ballast_top_half_width']:g} m"))
    if not g["ballast_top_half_width"] <= g["ballast_bottom_half_width"] < -g["ys1"]:
        out.append(("geometry.ballast_bottom_half_width", g["ballast_bottom_half_width"],
                    f"must lie between ballast_top_half_width = {g['ballast_top_half_width']:g} "
                    f"and |YS1| = {-g['ys1']:g} m (sloped shoulders)"))
    out.extend(_check_tracks(case))
    out.extend(_check_surface_load(case))
    out.extend(_check_static_start(case))
    out.extend(_check_track_ends(case))
    out.extend(_check_embankment(case))
    out.extend(_check_interfaces(case))
    if b["present"]:
        out.extend(_check_building(case))
    out.extend(_check_mesh_keys(case))
    out.extend(check_studies(case["study"]))
    out.extend(_check_dynamics(case))
    out.extend(_check_soil(case))
    out.extend(_check_measures(case))
    out.extend(_check_line_points(case))
    out.extend(check_uncertainty(case))
    return out


def _check_mesh_keys(case: CaseView) -> list[tuple[str, Any, str]]:
    """The mesh file, the refinement and the modal settings."""
    m = case["mesh"]
    out: list[tuple[str, Any, str]] = []
    if m["file"]:
        f = case.resolve(m["file"])
        if not f.is_file():
            out.append(("mesh.file", m["file"], f"file not found (looked for {f})"))
        elif f.suffix != ".msh":
            out.append(("mesh.file", m["file"], "must be a gmsh .msh file"))
    if m["refinement"] > 6:
        out.append(("mesh.refinement", m["refinement"],
                    "must be <= 6 (refinement 3 is already ~1.5M nodes)"))
    if case["modal.f_max"] == 0 and case["modal.n_modes"] < 1:
        out.append(("modal.n_modes", case["modal.n_modes"], "must be >= 1"))
    out.extend(_check_bands(case))
    need = case["modal.n_modes"] + 2 * case["modal.block_size"]
    if case["modal.method"] == "block_lanczos" and case["modal.f_max"] == 0 \
            and 0 < case["modal.max_basis"] < need:
        out.append(("modal.max_basis", case["modal.max_basis"],
                    f"must be 0 (automatic) or at least modal.n_modes + 2 modal.block_size = "
                    f"{need} (the Lanczos basis holds the wanted modes and two blocks)"))
    out.extend(_check_mbs(case))
    return out


def command_problems(case: CaseView, command: str) -> list[tuple[str, Any, str]]:
    """What a case asks of a command that the command cannot do (empty: nothing).

    Each stage declares its own refusals (``Stage(refuse=...)``,
    :meth:`~railvib_hpc.io.stage_protocol.Stage.refusals`: a case without a track on the
    modal path, ``modal.damping`` with supported track ends, a perfectly matched layer on
    the modal path); this collects those of the stages ``command`` runs
    (:func:`railvib_hpc.pipeline.refusals`: a pipeline's stages, a stage's own, none for
    ``check`` and ``study``), the first one in the stages' order, so the command line and
    the API refuse in one line before anything runs (before meshing). The registry is
    imported by name, as the product table imports it (this layer imports no stage).

    Parameters
    ----------
    case
        The validated case.
    command
        The ``railvib`` command (``run``, ``modal``, ``transient``, ...).

    Returns
    -------
    list
        ``(key, value, allowed)`` problems, for :class:`~railvib_hpc.errors.CaseError`.
    """
    from ..io.products import REGISTRY

    return importlib.import_module(REGISTRY).refusals(case, command)


def check_studies(tables: dict[str, dict[str, Any]]) -> list[tuple[str, Any, str]]:
    """Cross-key checks of the ``[study.KIND]`` tables; returns the problems.

    ``tables`` maps study kinds to their (type-checked) settings; keys in the problems are
    ``study.<kind>.<key>``.
    """
    out: list[tuple[str, Any, str]] = []
    conv = tables.get("convergence")
    if conv is not None and len(conv["levels"]) < 2:
        out.append(("study.convergence.levels", conv["levels"],
                    "need at least 2 refinement levels (3 for an observed order)"))
    refl = tables.get("reflection")
    if refl is not None:
        if len(refl["names"]) != len(refl["domains"]):
            out.append(("study.reflection.names", refl["names"],
                        f"needs one name per entry of domains ({len(refl['domains'])})"))
        if len(refl["domains"]) < 2:
            out.append(("study.reflection.domains", refl["domains"],
                        "need at least 2 domains to compare"))
        if any(x < 0 for d in refl["domains"] for x in d[1:]):
            out.append(("study.reflection.domains", refl["domains"],
                        "length and width changes must be >= 0 (only the depth change may be "
                        "negative: it raises the fixed base)"))
    return out
