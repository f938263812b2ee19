"""The solution: the ``[modal]``, ``[mbs]``, ``[transient]``, ``[output]`` and ``[probes]``
sections.
"""

from __future__ import annotations

from typing import Any

from .boundary import TRANSIENT_ENGINES
from .conditions import (
    BAND_SLICED,
    BLOCK_LANCZOS,
    DIRECT_ENGINE,
    IMEX_ENGINE,
    ON_TRACK,
    STATIC_CORRECTION,
)
from .param import _APDL, _THESIS_DAMPING, Param
from .parts import PROBE_ROLES

#: The sections of this module, in the schema's order.
SOLVERS_SECTIONS: dict[str, dict[str, Any]] = {
    "modal": {
        "n_modes": Param(300, "int", "-", "number of modes to extract", "pos",
                         source=f"{_APDL}: MODOPT,LANB,300; thesis §3"),
        "f_max": Param(0.0, "float", "Hz",
                       "if > 0: extract all modes below this frequency instead of n_modes "
                       "(block Lanczos: band-sliced, Sylvester inertia counts prove none is "
                       "missed; krylovschur: SLEPc spectrum slicing)", "nonneg"),
        "bands": Param([], "floats", "Hz",
                       "f_max: inner band edges, ascending in (0, f_max); [] = automatic split "
                       "from the inertia count at f_max (about modal.band_modes per band)",
                       applies=BAND_SLICED),
        "band_modes": Param(250, "int", "-",
                            "f_max, automatic split: target number of modes per band", "pos",
                            applies=BAND_SLICED),
        "band_groups": Param(1, "int", "-",
                             "f_max: bands solved concurrently, each on its own sub-communicator "
                             "of size ranks / band_groups (1: one band after the other on all "
                             "ranks)", "pos", applies=BAND_SLICED),
        "band_only": Param(0, "int", "-",
                           "f_max, array jobs: compute only band k (1-based) into <out>/bands/ "
                           "and stop; a run with 0 merges the cached bands (computing the "
                           "missing ones)", "nonneg", applies=BAND_SLICED),
        "damping_ratio": Param(0.03, "float", "-",
                               "modal damping ratio for all modes (modal.damping = 'uniform'; "
                               "with 'strain_energy': the rail pads' share)", "fraction",
                               source=_THESIS_DAMPING),
        "damping": Param("uniform", "str", "-",
                         "modal damping: the same ratio for every mode (the thesis), or per "
                         "material from each mode's strain-energy shares, zeta_i = sum_g "
                         "zeta_g E_ig / sum_g E_ig (ANSYS MP,DMPR; materials.*.damping_ratio), "
                         "Rayleigh (zeta_i = alpha / (2 omega_i) + beta omega_i / 2 with "
                         "modal.damping_ratio at damping.f1, damping.f2: exactly the damping "
                         "of the full-order model with damping.model = 'rayleigh' and no "
                         "absorbing faces), or full (the projected damping matrix Phi^T C Phi "
                         "of [damping] and the absorbing faces' dashpots, coupled modal "
                         "equations)",
                         choices=("uniform", "strain_energy", "rayleigh", "full")),
        "lumped_mass": Param(False, "bool", "-", "use lumped instead of consistent mass"),
        "hex_formulation": Param("bbar", "str", "-",
                                 "stiffness of the 8-node hexahedra: B-bar (ANSYS SOLID185 "
                                 "default, the thesis; too soft in bending when a slab or wall "
                                 "is one element thick), incompatible modes (SOLID185 "
                                 "KEYOPT(2)=3; bends correctly one element thick) or plain full "
                                 "integration", choices=("bbar", "incompatible", "full"),
                                 source=f"{_APDL}: ET,2,SOLID185 (default KEYOPT(2)=0: B-bar)"),
        "method": Param("block_lanczos", "str", "-",
                        "eigensolver: block shift-invert Lanczos (fast, many right-hand sides "
                        "per MUMPS solve) or SLEPc Krylov-Schur (with f_max: SLEPc spectrum "
                        "slicing)", choices=("block_lanczos", "krylovschur"),
                        source=f"{_APDL}: MODOPT,LANB (block Lanczos)"),
        "block_size": Param(32, "int", "-", "block Lanczos: right-hand sides per solve", "pos",
                            applies=BLOCK_LANCZOS),
        "out_of_core": Param("auto", "str", "-",
                             "MUMPS factor on disk (ICNTL(22)): auto = only when the in-core "
                             "factor would not fit in the available memory but the out-of-core "
                             "one does (block Lanczos); always; never (then a model too large "
                             "stops with a clear message)", choices=("auto", "always", "never")),
        "max_basis": Param(0, "int", "-",
                           "block Lanczos: basis size before a thick restart (0: 3 n_modes, "
                           "capped at 4 GB of basis vectors)", "nonneg", applies=BLOCK_LANCZOS),
        "shift_hz": Param(0.0, "float", "Hz",
                          "shift of the spectral transformation (modes nearest to it)",
                          "nonneg"),
        "tol": Param(1e-8, "float", "-", "relative residual tolerance of the eigenpairs", "pos"),
        "max_restarts": Param(100, "int", "-", "maximum restarts of the eigensolver", "pos"),
        "fix_sleeper_rotations": Param(True, "bool", "-",
                                       "fix all rotations of sleeper nodes (thesis, App. A)",
                                       source=f"{_APDL}: ESEL,S,MAT,,3 / D,ALL,ROTX..ROTZ,0",
                                       applies=ON_TRACK),
        "fix_rail_rotations_at_pads": Param(True, "bool", "-",
                                            "fix all rotations of rail nodes above the pads "
                                            "(thesis, App. A)",
                                            source=f"{_APDL}: NSEL,S,NODE,,7,177,5 / D,ALL,ROT*,0",
                                            applies=ON_TRACK),
    },
    "mbs": {
        "n_modes": Param(0, "int", "-", "modes used (0: all modes in modes.h5)", "nonneg"),
        "dt": Param(0.0, "float", "s",
                    "time step (0: automatic from the highest mode and the contact stiffness)",
                    "nonneg"),
        "points_per_period": Param(20, "int", "-",
                                   "automatic time step: steps per period of the fastest "
                                   "oscillation", "pos"),
        "store_every": Param(1, "int", "-", "store every n-th time step in mbs.h5", "pos"),
        "damping_modes": Param([], "floats", "-",
                               "modes (1-based) whose damping ratio is overridden"),
        "damping_ratios": Param([], "floats", "-",
                                "damping ratios of damping_modes (one per entry)"),
        "static_correction": Param(False, "bool", "-",
                                   "add the residual static flexibility of the modes not "
                                   "kept as residual modes with their mass and damping "
                                   "(modal truncation augmentation; needs static.h5 from the "
                                   "modal stage)"),
    },
    "transient": {
        "dt": Param(0.0, "float", "s",
                    "time step of the full-order time integration (0: automatic, the largest "
                    "step that divides output.dt and resolves transient.f_max with "
                    "transient.steps_per_period steps and, with a vehicle, crosses a rail "
                    "element in transient.steps_per_element steps)", "nonneg"),
        "f_max": Param(80.0, "float", "Hz",
                       "highest frequency of the analysis band (80 Hz: the top one-third-octave "
                       "band of the assessment); a coarser time step is warned about", "pos"),
        "steps_per_period": Param(20, "int", "-",
                                  "automatic time step: steps per period of transient.f_max "
                                  "(20: period error 0.8 % with the trapezoidal rule)", "pos"),
        "steps_per_element": Param(8, "int", "-",
                                   "automatic time step: steps while a wheel crosses one rail "
                                   "element (8: peak contact force within 0.3 % of half the "
                                   "step on the coarse thesis model)", "pos"),
        "rho_inf": Param(1.0, "float", "-",
                         "generalized-alpha (Chung-Hulbert) spectral radius at infinite "
                         "frequency: 1 = Newmark average acceleration (trapezoidal rule, no "
                         "numerical damping, energy conserving), < 1 damps the highest "
                         "frequencies (0.8: period error 0.86 % instead of 0.82 % at 20 steps "
                         "per period)",
                         "unit", applies=DIRECT_ENGINE),
        "engine": Param("direct", "str", "-",
                        "time integration of the full-order model: 'direct' (generalized-"
                        "alpha, one MUMPS factor of K_eff: unconditionally stable, memory "
                        "~n^(4/3)) or 'explicit' (central differences with the lumped mass: "
                        "memory and work per step linear in the DOFs, the step limited by the "
                        "largest natural frequency; needs modal.lumped_mass = true) or "
                        "'imex' (implicit-explicit, Hughes & Liu 1978: the elements of "
                        "transient.implicit_parts by the trapezoidal rule with one small "
                        "MUMPS factor, the rest (the soil) explicit with the lumped mass: the "
                        "step limited by the soil's elements only; needs modal.lumped_mass = "
                        "true)",
                        choices=TRANSIENT_ENGINES,
                        source="not in the thesis: the direct path (one MUMPS factor) is the "
                               "reference; explicit and imex are engines whose memory and "
                               "cost grow linearly (docs/transient.md)"),
        "implicit_elements": Param("parts", "str", "-",
                                   "transient.engine = 'imex': 'parts' integrates the parts "
                                   "of transient.implicit_parts implicitly; 'auto' also every "
                                   "solid element whose own stable step (its largest "
                                   "frequency with the lumped mass and its Rayleigh damping) is "
                                   "below the target step (transient.dt, or the band's step), "
                                   "at most the 5 % with the smallest steps: thin slices and "
                                   "heavily damped elements of the soil no longer set the "
                                   "step of the whole model",
                                   choices=("parts", "auto"),
                                   source="element-wise stable steps of an implicit-explicit "
                                          "partition (Hughes & Liu 1978; docs/transient.md)",
                                   applies=IMEX_ENGINE),
        "implicit_parts": Param(["track", "building"], "strs", "-",
                                "transient.engine = 'imex': the parts integrated implicitly "
                                "(part names, or the groups 'track' = rails, sleepers, pads, "
                                "under-sleeper pads, ballast mats and 'building' = the "
                                "building's parts and its base isolation); every other "
                                "element is explicit and sets the stable step",
                                source="Hughes & Liu 1978: the stiff, small track and "
                                       "building implicit, the soil explicit "
                                       "(docs/transient.md)", applies=IMEX_ENGINE),
        "checkpoint_interval": Param(120.0, "float", "s",
                                     "wall-clock time between checkpoints of the state (an "
                                     "interrupted run resumes from the last one; 0: none)",
                                     "nonneg"),
    },
    "output": {
        "dt": Param(0.001, "float", "s",
                    "time step of the reconstructed fields (a multiple of the MBS step; 0: every "
                    "step stored in mbs.h5)", "nonneg"),
        "window": Param([], "floats", "s",
                        "time window [t0, t1] of the reconstructed fields (empty: all)"),
        "float32": Param(False, "bool", "-", "store reconstructed fields in single precision"),
        "stress_times": Param([0.54, 0.61], "floats", "s",
                              "times of the element stress/strain fields (thesis: 0.54, 0.61 s)",
                              source="thesis Figs. 21-26: t = 0.54 s and 0.61 s"),
        "probes": Param([], "floats", "m",
                        "extra probe points as a flat list x1, y1, z1, x2, y2, z2, ..."),
        "probe_roles": Param([], "strs", "-",
                             "role of each extra probe point, in the order of output.probes "
                             "(empty: every point is 'ground'); 'floor' points are assessed "
                             "with the DIN 4150-3 floor limit, the others as foundations",
                             choices=PROBE_ROLES),
        "static_correction_rates": Param(False, "bool", "-",
                                         "with mbs.static_correction: add the correction also "
                                         "to velocities and accelerations (R g', R g''); off: "
                                         "the classical mode-acceleration method, displacements "
                                         "and stresses corrected, velocities and accelerations "
                                         "from the modes (R g'' carries the node-to-node "
                                         "stepping of the moving load far above the modal band)",
                                         applies=STATIC_CORRECTION),
    },
    "probes": {
        "line": Param([], "probe_lines", "-",
                      "free-field probe lines as [[probes.line]] tables with name, distances, "
                      "side and x (docs/sites.md): each distance is a probe <name>_<d>m of role "
                      "free_field on the ground, assessed by PPV, the largest 1 s running RMS "
                      "and the one-third-octave velocity spectrum; [] = none"),
    },
}
