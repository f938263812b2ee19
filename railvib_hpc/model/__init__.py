"""The finite-element model the modal and transient paths share: DOF map, elements, assembly.

Also the truncation faces' conditions, the Rayleigh damping, the supported track ends and the
MUMPS factor; PETSc code in ``model/petsc.py``.
"""
