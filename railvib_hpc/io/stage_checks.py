"""The data check of each stage file (:data:`CHECKS`): finite values and plausibility
against the model's sizes and the case's loads, on write and on reuse.

Each file format has one home in :mod:`railvib_hpc.io.formats`, with its layout, its check
(``check_<file>(path, full, context)``: a list of problems, empty when sound; ``full``
False when the content is vouched for by its record) and, where they sit in the io layer,
its writer and reader; :mod:`railvib_hpc.io.formats.checks` has what the checks share.
This table names the check of each row of :data:`~railvib_hpc.io.products.STAGE_FILES`.
"""

from __future__ import annotations

from .files import (
    BAND_CACHE,
    FIELDS_H5,
    MBS_H5,
    MESH_H5,
    MODAL_DAMPING_H5,
    MODES_H5,
    PROBES_H5,
    STATIC_H5,
    TRANSIENT_CHECKPOINT_H5,
    TRANSIENT_FIELDS,
    TRANSIENT_H5,
    TRANSIENT_PROBES,
)
from .formats.bands import check_band_cache
from .formats.fields import check_fields
from .formats.mbs import check_mbs
from .formats.mesh import check_mesh
from .formats.modal_damping import check_modal_damping
from .formats.modes import check_modes
from .formats.probes import check_probes
from .formats.static import check_static
from .formats.transient import check_checkpoint, check_transient

#: The data check of each stage file (by table name).
CHECKS = {MESH_H5: check_mesh, MODES_H5: check_modes, STATIC_H5: check_static,
          MODAL_DAMPING_H5: check_modal_damping, MBS_H5: check_mbs,
          FIELDS_H5: check_fields, PROBES_H5: check_probes,
          TRANSIENT_H5: check_transient, TRANSIENT_FIELDS: check_fields,
          TRANSIENT_PROBES: check_probes, TRANSIENT_CHECKPOINT_H5: check_checkpoint,
          BAND_CACHE: check_band_cache}
