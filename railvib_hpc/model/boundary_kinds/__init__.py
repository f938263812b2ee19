"""The boundary kinds of the truncation faces, one module each (registered in
:data:`railvib_hpc.boundary_registry.BOUNDARY_KINDS`)."""
