"""Input/output: HDF5 + XDMF files for ParaView, atomic writes, result reuse."""
