"""railvib-hpc: MPI-parallel FE + multibody prediction of train-induced building vibration."""

__version__ = "0.1.0"
