"""Reconstruction of nodal fields, stresses and probe histories from modal histories.

Thesis chapter 5: the response of the whole model follows from the modal coordinates of
the multibody simulation by superposition, ``u(t) = Phi q(t)``.

* :mod:`.fields` -- parallel, streamed GEMM reconstruction into ``fields.h5`` +
  ``fields.xdmf`` (:func:`reconstruct_fields`);
* :mod:`.stress` -- von Mises stress and equivalent strain of the hexahedra
  (:func:`element_stress`, parallel driver :func:`stress_from_fields`) and the bending
  moment of the rails (:func:`rail_bending_moment`);
* :mod:`.probes` -- exact probe histories from interpolated mode shapes
  (:func:`probe_modes`, :func:`probe_histories`, CSV/HDF5 writers);
* :mod:`.stage` -- the ``reconstruct`` stage (:func:`run_reconstruct_stage` for a case,
  :func:`reconstruct_outputs` for any modes/mbs pair) with input validation and reuse.
"""

from .fields import (
    FIELD_NAMES,
    OUTPUT_BUDGET_BYTES,
    block_steps_for_budget,
    node_range,
    reconstruct_fields,
    write_fields_xdmf,
)
from .probes import (
    ProbeError,
    locate_probes,
    mesh_probes,
    probe_histories,
    probe_modes,
    write_probes_csv,
    write_probes_h5,
)
from .stage import (
    ReconstructInputError,
    read_inputs,
    reconstruct_options,
    reconstruct_outputs,
    run_reconstruct_stage,
)
from .stress import (
    element_stress,
    hex_materials,
    rail_bending_moment,
    rail_moment_history,
    rail_moment_modes,
    rail_section,
    stress_from_fields,
    write_stress_xdmf,
)

__all__ = [
    "FIELD_NAMES",
    "OUTPUT_BUDGET_BYTES",
    "ProbeError",
    "ReconstructInputError",
    "block_steps_for_budget",
    "element_stress",
    "hex_materials",
    "locate_probes",
    "mesh_probes",
    "node_range",
    "probe_histories",
    "probe_modes",
    "rail_bending_moment",
    "rail_moment_history",
    "rail_moment_modes",
    "rail_section",
    "read_inputs",
    "reconstruct_fields",
    "reconstruct_options",
    "reconstruct_outputs",
    "run_reconstruct_stage",
    "stress_from_fields",
    "write_fields_xdmf",
    "write_probes_csv",
    "write_probes_h5",
    "write_stress_xdmf",
]
