"""Modal analysis: the eigensolvers and the modes of the model (K, M, C from ``model/``)."""
