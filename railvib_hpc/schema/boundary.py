"""The truncation of the soil box: its faces and their conditions, the time-domain
engines, the perfectly matched layers' defaults, the face conditions keys apply under, and
the ``[domain]``, ``[boundary]`` and ``[damping]`` sections.
"""

from __future__ import annotations

from typing import Any

from ..applies import Condition, any_of, includes, is_
from ..boundary_registry import BOUNDARY_KIND_NAMES
from ..time_engines import ENGINE_NAMES, PML_ENGINE_NAMES
from .conditions import ON_TRACK
from .param import Param

#: Conditions of a truncation face of the soil box (``[boundary]``): the registered boundary
#: kinds (:mod:`railvib_hpc.boundary_registry`; a kind registered later is allowed too).
BOUNDARY_TYPES = BOUNDARY_KIND_NAMES
#: Default frequency shift of the perfectly matched layers [1/s]: 2 pi x 0.5 Hz, half the
#: lowest one-third-octave band assessed (1 Hz); there omega / |i omega + alpha| = 0.89.
PML_ALPHA = 3.14159
#: The truncation faces of the soil box: x = min/max, y = min/max, z = min.
BOUNDARY_FACES = ("x_min", "x_max", "y_min", "y_max", "base")
#: The time integration engines of ``railvib transient`` (``transient.engine``), and those
#: that take ``pml`` faces, which the refusals of a layer name (the direct engine's layer is
#: implicit, the explicit and imex engines' explicit with ``M_e1`` and ``M_e2`` at the full
#: step or in K_eff; docs/transient.md): live views of the engines' declarations
#: (:mod:`railvib_hpc.time_engines`; an engine registered later is a choice too).
TRANSIENT_ENGINES = ENGINE_NAMES
PML_ENGINES = PML_ENGINE_NAMES


def _face(default: str, where: str) -> Param:
    return Param(default, "str", "-",
                 f"{where}: fixed (all displacements 0), roller (normal displacement 0), free, "
                 "absorbing (Lysmer-Kuhlemeyer dashpots rho c_P normal, rho c_S tangential "
                 "per unit area, from the soil behind the face), caughey (fixed, with a "
                 "graded Caughey absorbing layer inside the mesh, boundary.layer_*) or pml "
                 "(fixed, with a perfectly matched layer of boundary.layer_thickness inside "
                 "the mesh, boundary.pml_*; railvib transient only, any engine)",
                 choices=BOUNDARY_TYPES)


def _faces(kind: str, what: str, study: bool = False) -> Condition:
    """A truncation face of type ``kind`` (or, with ``study``, the reflection study's
    variants of that type, whose faces it sets)."""
    faces = [is_(f"boundary.{f}", kind) for f in BOUNDARY_FACES]
    text = f"{what} (boundary.x_min, x_max, y_min, y_max or base = {kind!r}"
    if study:
        faces.append(includes("study.reflection.boundaries", kind))
        text += f", or study.reflection.boundaries with {kind!r}"
    return any_of(*faces, what=text + ")")


ABSORBING_FACES = _faces("absorbing", "an absorbing face", study=True)
CAUGHEY_FACES = _faces("caughey", "a caughey face")
PML_FACES = _faces("pml", "a perfectly matched layer", study=True)
LAYER_FACES = any_of(CAUGHEY_FACES, _faces("pml", "a perfectly matched layer"),
                     what="a caughey or pml face (boundary.x_min, x_max, y_min, y_max or "
                          "base)")


#: The sections of this module, in the schema's order.
BOUNDARY_SECTIONS: dict[str, dict[str, Any]] = {
    "domain": {
        "extra_depth": Param(0.0, "float", "m", "extra subgrade depth below Z0", "nonneg"),
        "extra_width": Param(0.0, "float", "m", "extra soil width beyond the building (below YS4)",
                             "nonneg"),
        "extra_length": Param(0.0, "float", "m",
                              "extra soil length before X1 and after X4 (track unchanged)",
                              "nonneg"),
    },
    "boundary": {
        "x_min": _face("roller", "soil face at the start of the domain (x = min; the thesis: "
                       "roller)"),
        "x_max": _face("roller", "soil face at the end of the domain (x = max; the thesis: "
                       "roller)"),
        "y_min": _face("roller", "soil face beyond the building (y = min; the thesis: roller)"),
        "y_max": _face("roller", "soil face on the other side of the track (y = max; the "
                       "thesis: roller)"),
        "base": _face("fixed", "bottom of the subgrade (z = min; the thesis: fixed)"),
        "virtual_thickness": Param(0.0, "float", "m",
                                   "absorbing faces: add springs (lambda + 2 G) / t normal and "
                                   "G / t tangential per unit area, as if t metres of the same "
                                   "soil lay behind the face; they give the truncated model "
                                   "static support (0: dashpots only, the model may drift under "
                                   "a static load). For a static load the half-space's "
                                   "compliance needs t of 1.5-2.3 times the distance from the "
                                   "load to the faces (bench/spring_static_study.py, "
                                   "docs/verification.md)", "nonneg", applies=ABSORBING_FACES),
        "layer_thickness": Param(0.0, "float", "m",
                                 "caughey and pml faces: thickness of the absorbing layer, "
                                 "measured "
                                 "into the mesh from the face (part of the model: enlarge the "
                                 "domain by it, [domain])", "nonneg", applies=LAYER_FACES),
        "layer_damping": Param(0.3, "float", "-",
                               "caughey faces: Rayleigh damping ratio at the face (at "
                               "damping.f1 and f2), decreasing quadratically to 0 at the inner "
                               "edge of the layer", "fraction", applies=CAUGHEY_FACES),
        "pml_reflection": Param(1e-4, "float", "-",
                                "pml faces: target reflection coefficient R of the continuous "
                                "layer for a P wave at normal incidence; sets the profile's "
                                "largest damping d_max = (p + 1) c_P ln(1 / R) / (2 L) "
                                "(Collino & Tsogka 2001)", "fraction", applies=PML_FACES),
        "pml_power": Param(2.0, "float", "-",
                           "pml faces: exponent p of the damping profile d = d_max (xi / L)^p "
                           "over the depth xi into the layer (2 to 3: Collino & Tsogka 2001)",
                           "pos", applies=PML_FACES),
        "pml_alpha": Param(PML_ALPHA, "float", "1/s",
                           "pml faces: frequency shift alpha of the stretching 1 + d / (i omega "
                           "+ alpha) (complex frequency shifted PML, Kuzuoglu & Mittra 1996): "
                           "no memory grows under a static or slowly varying load; waves "
                           "below alpha / (2 pi) are absorbed less (default pi 1/s: 0.5 Hz, "
                           "half the lowest assessed band, where the attenuation is 89 % of "
                           "the classical layer's); 0: the classical PML", "nonneg",
                           applies=PML_FACES),
    },
    "damping": {
        "model": Param("rayleigh", "str", "-",
                       "damping matrix C of the full-order model (railvib transient, and "
                       "modal.damping = 'full'): rayleigh = alpha M + beta K with "
                       "modal.damping_ratio at damping.f1 and damping.f2; per_material = the "
                       "same per material with materials.*.damping_ratio (the rail pads: "
                       "modal.damping_ratio); none. Absorbing faces add their dashpots",
                       choices=("rayleigh", "per_material", "none")),
        "f1": Param(8.0, "float", "Hz",
                    "lower frequency at which the Rayleigh damping equals the damping ratio "
                    "(default: below the first soil mode of the thesis model, 9.1 Hz)", "pos"),
        "f2": Param(40.0, "float", "Hz",
                    "upper frequency at which the Rayleigh damping equals the damping ratio "
                    "(default: the 300-mode band of the thesis model, 42.7 Hz; above it the "
                    "damping grows in proportion to the frequency)", "pos"),
        "pads": Param(False, "bool", "-",
                      "add the rail pads' dashpots (pads.cx, cy, cz) to C (the thesis's 3 % "
                      "modal damping does not use them)", applies=ON_TRACK),
    },
}
