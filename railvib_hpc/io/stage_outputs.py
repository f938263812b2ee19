"""The stages' result types, declared once: what each stage returns and the API's results.

Each pipeline stage's ``compute`` returns one of these frozen objects (a
:class:`StageOutput`: ``reused``, ``summary``, and the stage's own fields); the API's
typed results (:class:`~railvib_hpc.api.MeshResult` and the others) inherit their fields
from them, so each field is declared here only. The module is light on purpose: it
imports the file names only, so the API imports it without loading the stage modules
(gmsh, PETSc, h5py) or numpy (imported when a result is built).

==========================  ===========  ==================================
output                      stage        API result
==========================  ===========  ==================================
:class:`MeshOutput`         mesh         :class:`~railvib_hpc.api.MeshResult`
:class:`ModesOutput`        modal        :class:`~railvib_hpc.api.ModalResult`
:class:`PassageOutput`      mbs          :class:`~railvib_hpc.api.MBSResult`
:class:`FieldsOutput`       reconstruct  :class:`~railvib_hpc.api.ReconstructResult`
:class:`AssessmentOutput`   assess       :class:`~railvib_hpc.api.AssessResult`
==========================  ===========  ==================================

Examples
--------
>>> from railvib_hpc.io.stage_outputs import ModesOutput
>>> list(ModesOutput.__dataclass_fields__)[:4]
['reused', 'summary', 'modes_h5', 'modes_xdmf']
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .files import (
    ASSESSMENT_JSON,
    MBS_H5,
    MESH_H5,
    MESH_MSH,
    MESH_REPORT_JSON,
    MESH_XDMF,
    MODES_H5,
    MODES_XDMF,
    STATIC_H5,
)

if TYPE_CHECKING:
    import numpy as np

__all__ = ["SOLVER_STATISTICS", "AssessmentOutput", "FieldsOutput", "MeshOutput", "ModesOutput",
           "PassageOutput", "StageOutput"]

#: The eigensolver's statistics a :class:`ModesOutput` holds (``solver_statistics``: those
#: of them its summary has, as recorded in ``modes.h5``; the studies' ``result.json``
#: copies them).
SOLVER_STATISTICS = ("factor_memory_gb", "time_factorization", "time_solve", "linear_solves",
                     "peak_rss_gb_total", "peak_rss_gb_per_rank", "ranks",
                     "time_assembly_total", "time_block_solves", "time_orthogonalization",
                     "max_relative_residual", "reduced")


@dataclass(frozen=True)
class StageOutput:
    """What ``compute`` returns; each stage's result type adds its own fields.

    Attributes
    ----------
    reused
        What it reused instead of computing (a bool, or per file; None for a stage that
        gives no reuse verdict, ``assess``); ``run.json`` records it.
    summary
        Its full summary (the statistics it printed and recorded).
    """

    reused: Any
    summary: Mapping[str, Any]


def _floats(values: Any, copy: bool = True) -> np.ndarray:
    """``np.array(values, dtype=float)`` (``copy=False``: ``np.asarray``); numpy is
    imported here, when a result is built, not with the module."""
    import numpy

    return numpy.array(values, dtype=float) if copy else numpy.asarray(values, dtype=float)


@dataclass(frozen=True)
class MeshOutput(StageOutput):
    """What the ``mesh`` stage returns (the API's ``MeshResult`` inherits these fields).

    Attributes
    ----------
    mesh_h5, mesh_xdmf, report_json
        The mesh in HDF5, its XDMF view (ParaView), the quality report.
    mesh_msh
        gmsh's mesh (None when ``mesh.file`` gave one).
    n_nodes, n_hexes
        Size of the mesh.
    min_scaled_jacobian, max_aspect_ratio
        Worst element quality.
    warnings
        The mesh check's warnings.
    """

    mesh_h5: Path
    mesh_xdmf: Path
    mesh_msh: Path | None
    report_json: Path
    n_nodes: int
    n_hexes: int
    min_scaled_jacobian: float
    max_aspect_ratio: float
    warnings: tuple[str, ...]

    @classmethod
    def of_report(cls, report: dict, out_dir: Path, user_mesh: bool) -> MeshOutput:
        """The output of a quality report
        (:func:`~railvib_hpc.mesh.stage.build_or_reuse_mesh`) in ``out_dir``."""
        q = report.get("quality", {})
        msh = out_dir / MESH_MSH
        return cls(reused=report.get("reused"), summary=report, mesh_h5=out_dir / MESH_H5,
                   mesh_xdmf=out_dir / MESH_XDMF,
                   mesh_msh=msh if not user_mesh and msh.exists() else None,
                   report_json=out_dir / MESH_REPORT_JSON,
                   n_nodes=int(q.get("n_nodes", 0)), n_hexes=int(q.get("n_hexes", 0)),
                   min_scaled_jacobian=float(q.get("min_scaled_jacobian", float("nan"))),
                   max_aspect_ratio=float(q.get("max_aspect_ratio", float("nan"))),
                   warnings=tuple(report.get("warnings", ())))


@dataclass(frozen=True)
class ModesOutput(StageOutput):
    """What the ``modal`` stage returns (the API's ``ModalResult`` inherits these
    fields).

    Attributes
    ----------
    modes_h5, modes_xdmf
        The modes and their ParaView view (None with ``modal.band_only``: one band only).
    static_h5
        The static solutions of the static correction (None when it is off).
    frequencies_hz
        The natural frequencies [Hz].
    n_dofs
        Free degrees of freedom of the model.
    max_orthonormality_error, max_relative_residual
        The eigensolver's checks (``max |Phi^T M Phi - I|``, largest relative residual).
    peak_rss_gb_total
        Peak memory over all ranks of the eigensolve [GB] (None when reused).
    n_nodes, n_hexes
        Size of the mesh of the modes (None with ``modal.band_only``).
    solver_statistics
        The eigensolver's statistics of :data:`SOLVER_STATISTICS` the modes were computed
        with (those recorded; ``peak_rss_gb_total`` as recorded, also when reused).
    """

    modes_h5: Path | None
    modes_xdmf: Path | None
    static_h5: Path | None
    frequencies_hz: np.ndarray
    n_dofs: int | None
    max_orthonormality_error: float | None
    max_relative_residual: float | None
    peak_rss_gb_total: float | None
    n_nodes: int | None = None
    n_hexes: int | None = None
    solver_statistics: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def of_summary(cls, summary: dict, frequencies, out_dir: Path, static_correction: bool,
                   mesh_size: tuple[int, int | None] | None = None) -> ModesOutput:
        """The output of a summary and the frequencies of its modes, in ``out_dir``
        (``mesh_size``: nodes and hexahedra of their mesh)."""
        def present(name: str) -> Path | None:
            return out_dir / name if (out_dir / name).exists() else None

        modes = present(MODES_H5) if not summary.get("band_only") else None
        return cls(reused=summary.get("reused"), summary=summary, modes_h5=modes,
                   modes_xdmf=present(MODES_XDMF) if modes else None,
                   static_h5=present(STATIC_H5) if static_correction else None,
                   frequencies_hz=_floats(frequencies if modes else [], copy=False),
                   n_dofs=summary.get("n_dofs"),
                   max_orthonormality_error=summary.get("max_orthonormality_error"),
                   max_relative_residual=summary.get("max_relative_residual"),
                   peak_rss_gb_total=None if summary.get("reused")
                   else summary.get("peak_rss_gb_total"),
                   n_nodes=mesh_size[0] if mesh_size else None,
                   n_hexes=mesh_size[1] if mesh_size else None,
                   solver_statistics={k: summary[k] for k in SOLVER_STATISTICS
                                      if k in summary})


@dataclass(frozen=True)
class PassageOutput(StageOutput):
    """What the ``mbs`` stage returns (the API's ``MBSResult`` inherits these fields).

    Attributes
    ----------
    mbs_h5
        The histories (contact forces, vehicle, modal coordinates).
    plots
        The PNG plots written with it.
    n_modes, dt, n_steps, t_end
        Modes used, time step [s], steps, end time [s].
    static_wheel_load, mean_contact_force, peak_contact_force, min_contact_force
        Per wheel [N] (the mean on the flexible rail).
    max_rail_deflection
        Largest rail deflection under a wheel [m].
    loss_of_contact_steps
        Steps in which a wheel lost contact.
    """

    mbs_h5: Path
    plots: tuple[Path, ...]
    n_modes: int
    dt: float
    n_steps: int
    t_end: float
    static_wheel_load: np.ndarray
    mean_contact_force: np.ndarray
    peak_contact_force: np.ndarray
    min_contact_force: np.ndarray
    max_rail_deflection: float
    loss_of_contact_steps: int

    @classmethod
    def of_stats(cls, stats: dict, out_dir: Path) -> PassageOutput:
        """The output of a passage's statistics (``stats`` of ``mbs.h5``) in ``out_dir``."""
        return cls(reused=stats.get("reused"), summary=stats, mbs_h5=out_dir / MBS_H5,
                   plots=tuple(sorted(out_dir.glob("mbs_*.png"))),
                   n_modes=int(stats["n_modes"]), dt=float(stats["dt"]),
                   n_steps=int(stats["n_steps"]), t_end=float(stats["t_end"]),
                   static_wheel_load=_floats(stats["static_wheel_load"]),
                   mean_contact_force=_floats(stats["mean_contact_force"]),
                   peak_contact_force=_floats(stats["peak_contact_force"]),
                   min_contact_force=_floats(stats["min_contact_force"]),
                   max_rail_deflection=float(stats["max_rail_deflection"]),
                   loss_of_contact_steps=int(stats["loss_of_contact_steps"]))


@dataclass(frozen=True)
class FieldsOutput(StageOutput):
    """What the ``reconstruct`` stage returns (the API's ``ReconstructResult`` inherits
    these fields).

    Attributes
    ----------
    fields_h5, fields_xdmf
        Displacement, velocity and acceleration of every node and their ParaView view.
    stress_xdmf
        Element stresses at ``output.stress_times`` (None when there are none).
    probes_h5
        Probe histories (and ``probes/<name>.csv``).
    probes
        ``{probe: its role and peaks}``
        (:func:`~railvib_hpc.reconstruct.probes.probe_peaks` with ``role``; the API's
        result holds them as ``{probe: ProbePeak}``).
    """

    fields_h5: Path
    fields_xdmf: Path | None
    stress_xdmf: Path | None
    probes_h5: Path
    probes: dict[str, Any]


@dataclass(frozen=True)
class AssessmentOutput(StageOutput):
    """What the ``assess`` stage returns (the API's ``AssessResult`` inherits these
    fields).

    Attributes
    ----------
    assessment_json
        Everything assessed (``results``, wave arrivals, thesis comparison).
    report_html, report_md, report_json
        The report.
    verdict
        ``{probe: passed}`` (True, False, or None when undetermined).
    max_utilisation
        ``{probe: largest value / limit over the binding standards}``.
    """

    assessment_json: Path
    report_html: Path | None
    report_md: Path | None
    report_json: Path | None
    verdict: dict[str, bool | None]
    max_utilisation: dict[str, float | None]

    @classmethod
    def of_summary(cls, summary: dict, out_dir: Path) -> AssessmentOutput:
        """The output of an assessment's summary
        (:func:`~railvib_hpc.assess.stage.assess_case`) in ``out_dir``; it is always
        computed anew and gives no reuse verdict (``reused`` None, null in ``run.json``)."""
        report = {k: Path(v) for k, v in summary.get("report", {}).items()}
        utilisation: dict[str, float | None] = {}
        for name, res in summary.get("results", {}).items():
            binding = [b.get("utilisation") for b in res.get("standards", {}).values()
                       if not b.get("comparison_only") and b.get("utilisation") is not None]
            utilisation[name] = float(max(binding)) if binding else None
        return cls(reused=None, summary=summary, assessment_json=out_dir / ASSESSMENT_JSON,
                   report_html=report.get("html"), report_md=report.get("markdown"),
                   report_json=report.get("json"), verdict=dict(summary.get("verdict", {})),
                   max_utilisation=utilisation)

