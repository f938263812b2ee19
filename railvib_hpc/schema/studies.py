"""The assessment and the studies: the ``[assessment]``, ``[uncertainty]`` and ``[study]``
sections.
"""

from __future__ import annotations

from typing import Any

from ..standards_registry import BUILDING_USES, DECLARED_STANDARDS, FTA_EVENTS, PERIODS
from ..uncertainty.reduced import MODELS as UQ_MODELS
from ..uncertainty.reduced import REDUCED_TOL
from ..uncertainty.sampling import METHODS as SAMPLING_METHODS
from .conditions import DIN4150_2, FTA, RANDOM_FIELDS, REDUCED_BASIS, REDUCED_MODEL
from .param import Param

#: Probes of the building whose responses the studies compare (names of the mesh probes).
BUILDING_PROBES = ("footing", "basement_wall", "slab1", "slab2")


def _study_probes() -> Param:
    return Param(list(BUILDING_PROBES), "strs", "-",
                 "mesh probes whose responses are compared (the building probes)", "name",
                 unique=True)


def _study_solver(what: str) -> Param:
    """``study.<kind>.solver`` of the studies that can run their variants either way."""
    return Param("modal", "str", "-",
                 "modal (modes + mbs, the thesis's method) or direct (railvib transient: the "
                 "full model in the time domain, causal, resolved up to transient.f_max where "
                 f"the mesh resolves it, else less, as its dispersion check says; {what})",
                 choices=("modal", "direct"))


#: The sections of this module, in the schema's order.
STUDIES_SECTIONS: dict[str, dict[str, Any]] = {
    "assessment": {
        "standards": Param(list(DECLARED_STANDARDS), "strs", "-",
                           "vibration criteria to evaluate: " + "; ".join(
                               f"{s.name} = {s.title}" for s in DECLARED_STANDARDS.values()),
                           choices=tuple(DECLARED_STANDARDS)),
        "building_use": Param("residential", "str", "-",
                              "use of the building: ISO multiplier, FTA category, VC curve, "
                              "DIN 4150-3 line", choices=tuple(BUILDING_USES)),
        "period": Param("day", "str", "-", "assessment period (ISO 10137, DIN 4150-2)",
                        choices=PERIODS),
        "fta_events": Param("frequent", "str", "-", "FTA event frequency", choices=FTA_EVENTS,
                            applies=FTA),
        "din4150_2_events": Param(0, "int", "-",
                                  "train passages per assessment period for DIN 4150-2 KB_FTr "
                                  "(0: not given; the middle band stays undetermined)",
                                  "nonneg", applies=DIN4150_2),
        "wave_threshold": Param(0.1, "float", "-",
                                "wave arrival: first time the acceleration magnitude exceeds "
                                "this fraction of its peak", "fraction"),
    },
    # Uncertain inputs (docs/uncertainty.md): `railvib study uncertainty CASE`
    # samples them; `railvib run` uses the nominal values (and field realisation 0: none).
    "uncertainty": {
        "parameter": Param([], "uncertain_parameters", "-",
                           "[[uncertainty.parameter]] tables: key (a numeric case key, or "
                           "soil.layers[k].<name>), distribution (normal, lognormal, uniform, "
                           "truncated_normal), mean (default: the case's value), std or cov, "
                           "low, high, name (label)"),
        "correlation": Param([], "matrix", "-",
                             "correlation matrix of the parameters' normal scores (Gaussian "
                             "copula), one row per [[uncertainty.parameter]] in their order; "
                             "[] = independent; symmetric, unit diagonal, positive definite"),
        "method": Param("lhs", "str", "-",
                        "sampling: lhs (Latin hypercube), mc (Monte Carlo) or sobol (Saltelli "
                        "design for Sobol' indices: samples * (parameters + 2) runs)",
                        choices=SAMPLING_METHODS),
        "samples": Param(32, "int", "-", "number of samples (sobol: base points, a power "
                         "of 2)", "pos"),
        "seed": Param(2026, "int", "-", "seed of the design and the random fields (every "
                      "sample is reproducible; the bootstrap has a fixed seed of its own)",
                      "nonneg"),
        "field": Param([], "random_fields", "-",
                       "[[uncertainty.field]] tables: layer (1-based soil layer), quantity "
                       "(E or rho), model (gaussian, exponential, matern), cov, len_h, len_v "
                       "[m], nu (Matern smoothness, default 1.5)"),
        "realisation": Param(0, "int", "-", "realisation of the random fields the model "
                             "uses: 0 none (the nominal layers), k >= 1 the k-th (seeded by "
                             "uncertainty.seed and k; the study sets it per sample)", "nonneg",
                             applies=RANDOM_FIELDS),
        "model": Param("full", "str", "-",
                       "how each sample is solved: full (its own mesh and eigensolve) or "
                       "reduced (the parametric reduced model on the nominal mesh, with "
                       "residual checks, fallback to full solves and reference samples; "
                       "docs/uncertainty.md)", choices=UQ_MODELS),
        "reduced_tol": Param(REDUCED_TOL, "float", "-",
                             "largest relative residual ||K phi - lambda M phi|| / ||K phi|| "
                             "of a reduced mode; a sample above it gets the full eigensolve "
                             "(on the nominal mesh)", "pos",
                             source="docs/uncertainty.md, 'The reduced model' (measured on "
                                    "the coarse thesis model)", applies=REDUCED_MODEL),
        "reduced_checks": Param(2, "int", "-",
                                "reference samples of the reduced model: drawn at random "
                                "(uncertainty.seed), each also solved in full and compared",
                                "nonneg", applies=REDUCED_MODEL),
        "basis": Param("", "str", "-",
                       "the reduced basis a sample's modes come from (set by railvib study "
                       "uncertainty with model = 'reduced'; empty: a plain model)",
                       applies=REDUCED_MODEL),
        "reference": Param(False, "bool", "-",
                           "with uncertainty.basis: solve in full too and record the reduced "
                           "model's error (set by the study on its reference samples)",
                           applies=REDUCED_BASIS),
    },
    # Settings of `railvib study KIND`: one table per study (``[study.convergence]``, ...);
    # ``--study-set key=value`` sets ``study.KIND.key``. Defaults chosen for the thesis model.
    "study": {
        "convergence": {
            "levels": Param([0.5, 0.75, 1.0, 1.25], "floats", "-",
                            "mesh.refinement of each level (at least 2, coarse to fine)",
                            "refinement", unique=True),
            "tolerance": Param(5.0, "float", "%", "verdict: converged when the estimated "
                               "error of the finest level is at most this many percent", "pos"),
            "n_frequencies": Param(5, "int", "-", "lowest natural frequencies compared", "pos"),
            "formal_order": Param(2.0, "float", "-", "order assumed with two levels or when "
                                  "the observed order is unreliable (trilinear hexahedra: 2)",
                                  "pos"),
            "solver": _study_solver("no natural frequencies are then compared"),
            "probes": _study_probes(),
        },
        "modes": {
            "n_modes": Param([50, 100, 200, 300], "ints", "-",
                             "numbers of modes used by the MBS (mbs.n_modes), from one modal "
                             "solve with the largest", "pos", unique=True),
            "static_correction": Param([False, True], "bools", "-",
                                       "run every mode count without and/or with the static "
                                       "correction", unique=True),
            "tolerance": Param(5.0, "float", "%", "accuracy asked for: modes needed to stay "
                               "within this many percent of the reference (most modes, "
                               "corrected if run)", "pos"),
            "probes": _study_probes(),
        },
        "reflection": {
            "domains": Param([[-1.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 2.0, 6.0],
                              [4.0, 4.0, 12.0]], "triples", "m",
                             "[depth, length, width] change of each domain: depth > 0 deepens "
                             "the subgrade (domain.extra_depth), < 0 raises the fixed base "
                             "(geometry.z0); length (each end) and width (beyond the building) "
                             ">= 0 (domain.extra_*); smallest first, the last is the reference. "
                             "Defaults: the thesis's Models 1-3 (3 m deep; the APDL's 4.8 m, "
                             "its '5 m'; + 2 m length, + 6 m width) and a larger reference",
                             unique=True),
            "names": Param(["model1", "model2", "model3", "larger"], "strs", "-",
                           "variant names, one per domain (default with other domains: "
                           "domain1, domain2, ...)", "name", unique=True),
            "threshold": Param(10.0, "float", "%", "verdict: reflections matter when a "
                               "building peak acceleration differs from the reference domain "
                               "by more than this many percent", "pos"),
            "band_hz": Param(0.0, "float", "Hz", "0: every domain uses modal.n_modes of the "
                             "case; > 0: every domain uses all its modes below this frequency "
                             "(the same band for all domains)", "nonneg"),
            "boundaries": Param(["case"], "strs", "-",
                                "boundary conditions of the truncation faces, each run on every "
                                "domain: case (the case file's [boundary]), thesis (rollers, "
                                "fixed base), absorbing (all five faces absorbing), pml (all "
                                "five faces perfectly matched layers of pml_thickness, added "
                                "outside each domain; solver = direct)",
                                choices=("case", "thesis", "absorbing", "pml"), unique=True),
            "pml_thickness": Param(4.0, "float", "m",
                                   "boundaries = pml: thickness of the layers (about 5 "
                                   "element layers of the coarse mesh's soil near the "
                                   "building, Collino & Tsogka 2001's smallest good layer)",
                                   "pos"),
            "solver": Param("modal", "str", "-",
                            "modal (modes + mbs, the thesis's method) or direct (railvib "
                            "transient: the full model in the time domain, causal; band_hz "
                            "does not apply)", choices=("modal", "direct")),
            "probes": _study_probes(),
        },
        "speed": {
            "speeds": Param([10.0, 20.0, 30.0, 40.0, 50.0, 60.0], "floats", "m/s",
                            "vehicle speeds (one MBS run each on the same modes); without a track "
                            "(track.count = 0, solver = direct): the moving load's, load.speed",
                            "pos",
                            unique=True),
            "solver": _study_solver("every speed is then a full-order run, no shared modes"),
            "probes": _study_probes(),
        },
        "mitigation": {
            "measures": Param([
                "soft_pads: pads.kz=1.2e8",
                "open_trench: trench.type=open; trench.distance=6.0; trench.width=0.6; "
                "trench.depth=3.0",
                "filled_trench: trench.type=filled; trench.distance=6.0; trench.width=0.6; "
                "trench.depth=3.0",
                "wib: wib.type=block; wib.width=6.0; wib.depth=1.0; wib.thickness=1.0"],
                "strs", "-",
                "the measures, each 'name: key=value; key=value' (case overrides, TOML "
                "values). Defaults: soft rail pads (120 kN/mm instead of the thesis's "
                "7,000), an open and an EPS-filled trench 0.6 m wide and 3 m deep 6 m from "
                "the track, and a 6 m wide, 1 m thick wave-impeding block 1 m under the "
                "track", unique=True),
            "same_mesh": Param(True, "bool", "-",
                               "compare a measure that changes the soil geometry (trench.*, "
                               "wib.*) with a reference on its own mesh (the same lines, no "
                               "measure) instead of the baseline: the insertion loss is then "
                               "the measure's, not the mesh's"),
            "solver": _study_solver("every variant, the references included"),
            "probes": _study_probes(),
        },
        "uncertainty": {
            "confidence": Param(0.95, "float", "-", "confidence level of the intervals "
                                "(percentile bootstrap, Wilson, Sobol' bootstrap)", "fraction"),
            "solver": _study_solver("every sample is then a full-order run"),
            "probes": _study_probes(),
        },
        "thesis": {
            "n_modes": Param(300, "int", "-", "the thesis's mode count (mbs.n_modes of the "
                             "count variants; the band must hold at least this many)", "pos"),
            "band_hz": Param(57.87, "float", "Hz", "the thesis's band: the shared model has "
                             "every mode below it (modal.f_max), the band variants use them "
                             "all", "pos"),
            "drop_heights": Param([0.0, 1e-5, 1e-4], "floats", "m",
                                  "wheelset drop heights (vehicle.drop_height; 0: start at "
                                  "rest): the thesis's unspecified start", "nonneg",
                                  unique=True),
            "contact_damping": Param([0.0], "floats", "N s/m^2",
                                     "Hertz contact damping C of the drops "
                                     "(vehicle.contact_damping; the thesis gives none)",
                                     "nonneg", unique=True),
            "probes": Param([*BUILDING_PROBES, "basement_wall_far"], "strs", "-",
                            "mesh probes whose responses are compared (the building probes "
                            "and the thesis's wave-arrival point)", "name", unique=True),
        },
    },
}
