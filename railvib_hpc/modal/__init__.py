"""Modal analysis: DOFs, distributed K and M, the eigensolvers and the modes of the model."""
