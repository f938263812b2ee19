"""The presets: the thesis's Table I values where they differ from the APDL script, each
with its source, and :func:`source`, where a key's value comes from in a preset.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from .param import _T1, Param
from .tree import SCHEMA


class PresetValue(NamedTuple):
    """A preset's value of one key and where it comes from."""

    value: Any
    source: str


#: Values of the thesis's Table I where it differs from the APDL script
#: (../shared/reference/benchmarks.md section 3), each with its source. Layer depths are the
#: same in both presets: Table I's "ballast 4.8 m" contradicts the APDL z-levels and
#: the thesis's own wave speeds. Table I gives neither torsion constants nor the
#: sleeper's lateral second moment: those keep the APDL section's values.
_PRESET_VALUES: dict[str, dict[str, PresetValue]] = {
    "apdl": {},
    "table1": {
        "materials.ballast.nu": PresetValue(0.3, f"{_T1}: Poisson's ratio of the ballast 0.3"),
        "materials.ballast.rho": PresetValue(1300.0, f"{_T1}: density of the ballast 1300"),
        "materials.subballast.nu": PresetValue(
            0.35, f"{_T1}: Poisson's ratio of the subballast 0.35"),
        "materials.subgrade.nu": PresetValue(0.35, f"{_T1}: Poisson's ratio of the subgrade 0.35"),
        "materials.sleeper.rho": PresetValue(2750.0, f"{_T1}: density of a sleeper 2750"),
        **{f"pads.k{d}": PresetValue(26.5e7, f"{_T1}: stiffness coefficient of a pad 26.5e7")
           for d in "xyz"},
        **{f"pads.c{d}": PresetValue(4.6e4, f"{_T1}: damping coefficient of a pad 4.6e4")
           for d in "xyz"},
        "sections.rail.area": PresetValue(
            64.5e-4, f"{_T1}: cross-sectional area of the rail 64.5e-4"),
        "sections.rail.iyy": PresetValue(2010e-8, f"{_T1}: second moment of the rail Iyy 2010e-8"),
        "sections.rail.izz": PresetValue(326e-8, f"{_T1}: second moment of the rail Izz 326e-8"),
        "sections.rail.shear_coefficient_y": PresetValue(
            0.34, f"{_T1}: Timoshenko shear coefficient 0.34"),
        "sections.rail.shear_coefficient_z": PresetValue(
            0.34, f"{_T1}: Timoshenko shear coefficient 0.34 (one value given, used for both "
            "planes)"),
        "sections.sleeper.area": PresetValue(
            513.8e-4, f"{_T1}: cross-sectional area of a sleeper 513.8e-4"),
        "sections.sleeper.iyy": PresetValue(
            18907e-8, f"{_T1}: second moment of a sleeper 18907e-8"),
        "sections.sleeper.shear_coefficient_y": PresetValue(
            0.83, f"{_T1}: Timoshenko shear coefficient 0.83"),
        "sections.sleeper.shear_coefficient_z": PresetValue(
            0.83, f"{_T1}: Timoshenko shear coefficient 0.83 (one value given, used for both "
            "planes)"),
    },
}
#: The keys each preset sets and their values: ``PRESETS[preset][key]`` (``apdl``: none, the
#: schema defaults).
PRESETS: dict[str, dict[str, Any]] = {
    name: {key: entry.value for key, entry in values.items()}
    for name, values in _PRESET_VALUES.items()}
#: Where each preset value comes from: ``PRESET_SOURCES[preset][key]``; the defaults' own
#: sources are :attr:`Param.source`.
PRESET_SOURCES: dict[str, dict[str, str]] = {
    name: {key: entry.source for key, entry in values.items()}
    for name, values in _PRESET_VALUES.items()}


def source(key: str, preset: str = "apdl") -> str:
    """Where the value of ``key`` comes from in ``preset`` ('' for program settings).

    A key the preset does not set takes the source of its default (:attr:`Param.source`).
    """
    own = PRESET_SOURCES.get(preset, {}).get(key)
    if own:
        return own
    node: Any = SCHEMA
    for part in key.split("."):
        if not isinstance(node, dict) or part not in node:
            return ""
        node = node[part]
    return node.source if isinstance(node, Param) else ""
