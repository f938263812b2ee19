"""File names: every file railvib writes into an output folder, each spelled once, here.

The stages, the product table (:data:`~railvib_hpc.io.products.STAGE_FILES`), its data
checks, the run record, the API and the studies name their files with these constants;
no other code path spells an output file name. A product's *table name* is its file
name, except for the full-order solution's ``fields.h5`` and ``probes.h5``, whose table
names are :data:`TRANSIENT_FIELDS` and :data:`TRANSIENT_PROBES`
(:attr:`~railvib_hpc.io.products.StageFile.filename` is the name on disk).

An output folder ``<out>``::

    mesh.msh  mesh.h5  mesh.xdmf  mesh_report.json           railvib mesh
    modes.h5  modes.xdmf  static.h5  modal_damping.h5        railvib modal
    bands/index.json  bands/...                              the modal band cache
    mbs.h5                                                   railvib mbs
    fields.h5  fields.xdmf  stress.xdmf  probes.h5  probes/  railvib reconstruct
    assessment.json  report.md  report.html  report.json     railvib assess
    run.json                                                 the run record
    .railvib/<file>.json  .railvib/lock                      content records, the lock
    transient/                                               railvib transient (its own
        transient.h5  transient_checkpoint.h5  fields.h5 ... folder, by default)

A study variant's folder holds ``result.json`` (or ``failed.json``) besides the files of
the stages it ran.
"""

from __future__ import annotations

#: Folder of the content records, the lock and crash logs inside an output folder.
RECORD_DIR = ".railvib"
#: The lock file of an output folder (in :data:`RECORD_DIR`).
LOCK_FILE = "lock"
#: The run record of an output folder.
RUN_FILE = "run.json"

#: ``railvib mesh``: the gmsh mesh, the mesh, its XDMF view and its report.
MESH_MSH = "mesh.msh"
MESH_H5 = "mesh.h5"
MESH_XDMF = "mesh.xdmf"
MESH_REPORT_JSON = "mesh_report.json"

#: ``railvib modal``: the modes, their XDMF view, the static fields, the projected damping.
MODES_H5 = "modes.h5"
MODES_XDMF = "modes.xdmf"
STATIC_H5 = "static.h5"
MODAL_DAMPING_H5 = "modal_damping.h5"
#: The band cache of the band-sliced modal solve: a folder and its index.
BANDS_DIR = "bands"
BAND_INDEX_JSON = "index.json"
#: The band cache's table name: its index, where its provenance is
#: (:mod:`railvib_hpc.io.formats.bands`).
BAND_CACHE = f"{BANDS_DIR}/{BAND_INDEX_JSON}"

#: ``railvib mbs``: the vehicle passage in modal coordinates.
MBS_H5 = "mbs.h5"

#: ``railvib reconstruct`` (and ``railvib transient``): the fields, their XDMF views, the
#: probe histories and the folder of their CSV files.
FIELDS_H5 = "fields.h5"
FIELDS_XDMF = "fields.xdmf"
STRESS_XDMF = "stress.xdmf"
PROBES_H5 = "probes.h5"
PROBES_CSV_DIR = "probes"

#: ``railvib assess``: the assessment and its reports (a study's report has the same names).
ASSESSMENT_JSON = "assessment.json"
REPORT_MD = "report.md"
REPORT_HTML = "report.html"
REPORT_JSON = "report.json"

#: ``railvib transient``: its subfolder of the output folder (the default of ``--out``),
#: the solution and its checkpoint, and the table names of its fields and probes.
TRANSIENT_DIR = "transient"
TRANSIENT_H5 = "transient.h5"
TRANSIENT_CHECKPOINT_H5 = "transient_checkpoint.h5"
TRANSIENT_FIELDS = f"transient:{FIELDS_H5}"
TRANSIENT_PROBES = f"transient:{PROBES_H5}"

#: A study variant: its result, or the record of its failure.
RESULT_JSON = "result.json"
#: ``railvib study uncertainty``: the design and the outputs per sample.
UNCERTAINTY_H5 = "uncertainty.h5"
FAILED_JSON = "failed.json"

#: Every file railvib writes at the top of an output folder (or of a study's variant
#: folder): a folder without railvib's record (:data:`RECORD_DIR`) that holds one of them
#: holds someone else's file, which a run would overwrite
#: (:func:`railvib_hpc.io.out_folder.output_folder_problem`).
OUTPUT_NAMES = (MESH_MSH, MESH_H5, MESH_XDMF, MESH_REPORT_JSON, MODES_H5, MODES_XDMF,
                STATIC_H5, MODAL_DAMPING_H5, MBS_H5, FIELDS_H5, FIELDS_XDMF, STRESS_XDMF,
                PROBES_H5, ASSESSMENT_JSON, REPORT_MD, REPORT_HTML, REPORT_JSON, RUN_FILE,
                TRANSIENT_H5, TRANSIENT_CHECKPOINT_H5, RESULT_JSON, UNCERTAINTY_H5,
                FAILED_JSON)
