"""Batched pure-numpy finite-element kernels (hexahedra, Timoshenko beams, springs).

Element matrices are computed for whole batches of elements at once, as arrays of
shape (nel, ndof, ndof); :mod:`.assemble_serial` assembles them for reference runs.
"""

from .assemble_serial import assemble_matrix, assemble_vector, element_dofs, eliminate_dofs
from .beam import (
    beam_frames,
    beam_mass,
    beam_stiffness,
    beam_transformation,
    shear_deformation_factors,
    shear_modulus,
)
from .hex8 import (
    ElementGeometryError,
    hex8_lumped_mass_diagonal,
    hex8_mass,
    hex8_stiffness,
    hex8_strain_displacement,
    hex8_volume,
)
from .material import isotropic_elasticity, isotropic_elasticity_batch
from .modes import lowest_modes, mass_normalise
from .spring import damper_matrices, spring_dofs, spring_matrices

__all__ = [
    "ElementGeometryError",
    "assemble_matrix",
    "assemble_vector",
    "beam_frames",
    "beam_mass",
    "beam_stiffness",
    "beam_transformation",
    "damper_matrices",
    "element_dofs",
    "eliminate_dofs",
    "hex8_lumped_mass_diagonal",
    "hex8_mass",
    "hex8_stiffness",
    "hex8_strain_displacement",
    "hex8_volume",
    "isotropic_elasticity",
    "isotropic_elasticity_batch",
    "lowest_modes",
    "mass_normalise",
    "shear_deformation_factors",
    "shear_modulus",
    "spring_dofs",
    "spring_matrices",
]
