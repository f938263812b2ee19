"""The parametric building: column grid, levels, parts and probes (pure Python, no gmsh).

The building stands in the excavation ``[X2, X3] x [YS3, YS2]`` (``geometry``), its
base (the underside of the footings) at ``ZBB``. It is a concrete frame:

* column lines at ``footing_size / 2`` inside the plan edges and ``spans_x`` /
  ``spans_y`` apart (``bays_x``, ``bays_y`` equal spans when no spans are given);
* square columns of side ``column_size`` on every crossing of column lines, from the
  footing top to the underside of the top slab;
* ``storeys`` slabs, ``slab_thickness`` thick, out to the outer column faces; slab 1's
  underside ``z_slab1_base`` above ZBB, each further storey ``z_slab2_base -
  z_slab1_base`` higher, or each at its own level (``slab_bases``);
* beams ``beam_depth`` deep and ``column_size`` wide along every column line under every
  slab, and grade beams on the footings' top between the footings;
* a basement wall ``wall_thickness`` thick round the plan, from the base to the ground;
* foundations ``footing_height`` thick: ``pad`` footings ``footing_size`` square under
  every column, ``strip`` footings ``footing_size`` wide under every column line, or a
  ``raft`` under the whole plan.

The thesis's building (APDL, Appendix A) is the instance with 2 storeys, 1 x 1 bays and
pad footings: its lines, parts and probes are the ones the layout had before the
building became parametric (``tests/mesh/test_building.py``).

Probes: ``footing`` (top centre of the footing nearest the track at x = first column
line), ``basement_wall`` / ``basement_wall_far`` (outer face of the wall facing the
track, at mid-length / at x = X3, mid-height), ``slab<k>`` (top of slab k at the plan
centre) and, per slab and bay, ``slab<k>_x<i>y<j>_mid`` (top of the slab at mid-span of
bay (i, j)) and ``slab<k>_x<i>y<j>_corner`` (top of the slab at the panel's corner by
the column faces, on the side of the first column line and of the track). Bays count
from X2 (``i``) and from the face nearest the track (``j``).

A building turned by whole quarter turns (``building.rotation``,
:func:`railvib_hpc.site.quarter_turns`) is laid out turned: the fields stay in its own
frame, its lines, parts and probes come turned about the plan centre (the plan's length and
width exchanged for an odd number, :func:`railvib_hpc.site.placed_plan`). The rest of the
turn twists the mesh afterwards (:mod:`railvib_hpc.mesh.turn`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import Case
from ..site import quarter_turns, slab_bases, turn_quarters

#: Role of the building's named probes (:data:`railvib_hpc.schema.PROBE_ROLES`).
ROLE_FLOOR, ROLE_WALL, ROLE_FOUNDATION = "floor", "wall", "foundation"


def column_lines(lo: float, hi: float, footing: float, bays: int, spans: list[float]
                 ) -> np.ndarray:
    """Column-centre coordinates from ``lo + footing/2``, ``spans`` apart (equal spans when
    empty) up to ``hi - footing/2``."""
    first, last = lo + footing / 2, hi - footing / 2
    if spans:
        return first + np.concatenate(([0.0], np.cumsum(spans)))
    return np.linspace(first, last, bays + 1)


@dataclass(frozen=True)
class Building:
    """Geometry of the building frame in model coordinates.

    Attributes
    ----------
    cx, cy
        Column-line coordinates; ``cx`` ascending from X2, ``cy`` descending from the face
        nearest the track (YS2).
    plan
        ``(x_lo, x_hi, y_lo, y_hi)``: the excavation.
    zbb, z_ground
        Building base and ground level.
    slab_bases
        Underside of every slab above ZBB, bottom up.
    quarters
        Whole quarter turns of the building about ``centre``, counter-clockwise
        (:func:`railvib_hpc.site.quarter_turns` of ``building.rotation``). The fields above
        are in the building's own frame; its lines, parts and probes are given turned.
    centre
        The plan centre ``(XBB, YBB)``.
    """

    cx: np.ndarray
    cy: np.ndarray
    plan: tuple[float, float, float, float]
    zbb: float
    z_ground: float
    slab_bases: np.ndarray
    footing_size: float
    footing_height: float
    column_size: float
    beam_depth: float
    slab_thickness: float
    wall_thickness: float
    foundation: str
    quarters: int = 0
    centre: tuple[float, float] = (0.0, 0.0)

    @classmethod
    def of_case(cls, case: Case) -> Building:
        """The building of a validated case."""
        g, b = case["geometry"], case["building"]
        cx = column_lines(g["x2"], g["x3"], b["footing_size"], b["bays_x"], b["spans_x"])
        cy = -column_lines(-g["ys2"], -g["ys3"], b["footing_size"], b["bays_y"], b["spans_y"])
        bases = np.array(slab_bases(case))
        return cls(cx=cx, cy=cy, plan=(g["x2"], g["x3"], g["ys3"], g["ys2"]), zbb=g["zbb"],
                   z_ground=g["z1"], slab_bases=bases, footing_size=b["footing_size"],
                   footing_height=b["footing_height"], column_size=b["column_size"],
                   beam_depth=b["beam_depth"], slab_thickness=b["slab_thickness"],
                   wall_thickness=b["wall_thickness"], foundation=b["foundation"],
                   quarters=quarter_turns(b["rotation"])[0],
                   centre=(0.5 * (g["x2"] + g["x3"]), 0.5 * (g["ys2"] + g["ys3"])))

    # ------------------------------------------------------------------ lines and levels
    def x_lines(self) -> list[float]:
        """Breakpoints along the model's x, the building turned: footing, column and wall
        faces."""
        return self._turned_lines(axis=0)

    def y_lines(self) -> list[float]:
        """Breakpoints along the model's y, the building turned: footing, column and wall
        faces."""
        return self._turned_lines(axis=1)

    def _turned_lines(self, axis: int) -> list[float]:
        """The own frame's x lines (an even number of quarter turns) or y lines (odd) that
        the turn lays along the model's ``axis``."""
        x0, y0 = self.centre
        if (self.quarters + axis) % 2 == 0:        # own x lines (constant own x)
            own = self._lines(self.cx, self.plan[0], self.plan[1])
            points = [turn_quarters(v, y0, self.quarters, self.centre) for v in own]
        else:                                      # own y lines
            own = self._lines(self.cy, self.plan[2], self.plan[3])
            points = [turn_quarters(x0, v, self.quarters, self.centre) for v in own]
        return [float(p[axis]) for p in points]

    def _lines(self, c: np.ndarray, lo: float, hi: float) -> list[float]:
        fs, cs, wt = self.footing_size, self.column_size, self.wall_thickness
        out = [lo, hi, lo + wt, hi - wt]
        for x in c:
            out += [x - fs / 2, x + fs / 2, x - cs / 2, x + cs / 2]
        return [v for v in out if lo - 1e-9 <= v <= hi + 1e-9]

    def levels_below(self) -> list[float]:
        """z levels of the building below the ground: base, footing top, grade-beam top."""
        fh = self.footing_height
        return [self.zbb, self.zbb + fh, self.zbb + fh + self.beam_depth]

    def levels_above(self) -> list[float]:
        """z levels above the ground: every beam underside, slab underside and slab top."""
        out = []
        for s in self.slab_bases:
            z = self.zbb + float(s)
            out += [z - self.beam_depth, z, z + self.slab_thickness]
        return out

    @property
    def top(self) -> float:
        """z of the roof (top of the top slab)."""
        return self.zbb + float(self.slab_bases[-1]) + self.slab_thickness

    def describe(self) -> str:
        """One line: storeys, bays, spans, foundation and height."""
        def spans(c: np.ndarray) -> str:
            return ", ".join(f"{v:g}" for v in np.round(np.abs(np.diff(c)), 6))

        n = len(self.slab_bases)
        return (f"{n} storey{'s' if n > 1 else ''}, {len(self.cx) - 1} x {len(self.cy) - 1} bays "
                f"(spans x {spans(self.cx)} m, y {spans(self.cy)} m), {self.foundation} "
                f"foundation, basement {self.z_ground - self.zbb:g} m deep, roof "
                f"{self.top - self.z_ground:g} m above the ground")

    # ------------------------------------------------------------------ classification
    def part(self, x: float, y: float, z: float) -> str | None:
        """The part of a block centred at ``(x, y, z)`` (model axes) in the plan above ZBB
        (None: empty).

        Footings take precedence over the wall, the wall over columns, columns over beams.
        """
        x, y = turn_quarters(x, y, -self.quarters, self.centre)      # to the own frame
        w = z - self.zbb
        fs, cs, wt = self.footing_size, self.column_size, self.wall_thickness
        dx, dy = np.min(np.abs(self.cx - x)), np.min(np.abs(self.cy - y))
        on_x_line, on_y_line = dx < cs / 2, dy < cs / 2      # x line: constant x
        x_lo, x_hi, y_lo, y_hi = self.plan
        at_wall = min(x - x_lo, x_hi - x, y - y_lo, y_hi - y) < wt
        below_ground = z < self.z_ground
        if w < self.footing_height:
            if self.foundation == "raft" or (
                    self.foundation == "strip" and (dx < fs / 2 or dy < fs / 2)) or (
                    self.foundation == "pad" and dx < fs / 2 and dy < fs / 2):
                return "footing"
            if at_wall:
                return "wall"
            if on_x_line or on_y_line:
                return "beam"
            return None
        if below_ground and at_wall:
            return "wall"
        in_slab = [s < w < s + self.slab_thickness for s in self.slab_bases]
        below_top = w < self.slab_bases[-1]
        if on_x_line and on_y_line and below_top and not any(in_slab):
            return "column"
        inside = (self.cx[0] - cs / 2 < x < self.cx[-1] + cs / 2
                  and self.cy[-1] - cs / 2 < y < self.cy[0] + cs / 2)
        if not inside:
            return None
        beam_level = w < self.footing_height + self.beam_depth or any(
            s - self.beam_depth < w < s for s in self.slab_bases)
        if beam_level and (on_x_line or on_y_line):
            return "beam"
        if any(in_slab):
            return "slab"
        return None

    # ------------------------------------------------------------------ probes
    def probes(self) -> dict[str, tuple[tuple[float, float, float], str]]:
        """The building's named probes: name -> (point, role), named in its own frame and
        placed turned by its quarter turns."""
        out = {}
        for name, ((x, y, z), role) in self._own_probes().items():
            xt, yt = turn_quarters(x, y, self.quarters, self.centre)
            out[name] = ((float(xt), float(yt), z), role)
        return out

    def _own_probes(self) -> dict[str, tuple[tuple[float, float, float], str]]:
        """The named probes in the building's own frame."""
        x_lo, x_hi, y_lo, y_hi = self.plan
        xc, yc = 0.5 * (x_lo + x_hi), 0.5 * (y_lo + y_hi)
        z_wall = self.zbb + 0.5 * (self.z_ground - self.zbb)
        out = {
            # top centre of the footing nearest the track, first reached by the train
            "footing": ((float(self.cx[0]), float(self.cy[0]), self.zbb + self.footing_height),
                        ROLE_FOUNDATION),
            # outer face of the basement wall facing the track, mid-length, mid-height
            "basement_wall": ((xc, y_hi, z_wall), ROLE_WALL),
            # the same wall's far end (x = X3), mid-height: the thesis's 20.2 m wave-arrival
            # point (20.2 m from the far rail at the entry of the flexible track, section 6.6)
            "basement_wall_far": ((x_hi, y_hi, z_wall), ROLE_WALL),
        }
        half = self.column_size / 2
        for k, s in enumerate(self.slab_bases, start=1):
            z = self.zbb + float(s) + self.slab_thickness
            out[f"slab{k}"] = ((xc, yc, z), ROLE_FLOOR)
            for i in range(len(self.cx) - 1):
                for j in range(len(self.cy) - 1):
                    name = f"slab{k}_x{i + 1}y{j + 1}"
                    mid = (0.5 * float(self.cx[i] + self.cx[i + 1]),
                           0.5 * float(self.cy[j] + self.cy[j + 1]), z)
                    corner = (float(self.cx[i]) + half, float(self.cy[j]) - half, z)
                    out[f"{name}_mid"] = (mid, ROLE_FLOOR)
                    out[f"{name}_corner"] = (corner, ROLE_FLOOR)
        return out


def building_line(case: Case) -> str:
    """What the building is, in one line (:meth:`Building.describe`), or that there is none
    (``building.present = false``)."""
    if not case["building.present"]:
        return "none (building.present = false: the free field alone)"
    return Building.of_case(case).describe()


def storey_of_probe(name: str) -> int | None:
    """The storey of a building floor probe named ``slab<k>...`` (None for other names)."""
    import re

    hit = re.match(r"slab(\d+)(?:_|$)", name)
    return int(hit.group(1)) if hit else None
