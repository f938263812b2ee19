"""The file formats of an output folder: one module each, with its layout, writer, reader and
check.

============================  ======================  =====================================
file                          module                  writer and reader
============================  ======================  =====================================
``mesh.h5``                   :mod:`.mesh`            :mod:`railvib_hpc.mesh.mesh_io`
``modes.h5``, ``modes.xdmf``  :mod:`.modes`           here
``static.h5``                 :mod:`.static`          :mod:`railvib_hpc.modal.static`
``modal_damping.h5``          :mod:`.modal_damping`   here
``bands/`` (the band cache)   :mod:`.bands`           here
``mbs.h5``                    :mod:`.mbs`             :mod:`railvib_hpc.mbs.stage`
``fields.h5``                 :mod:`.fields`          :mod:`railvib_hpc.reconstruct.fields`,
                                                      :mod:`railvib_hpc.transient.output`
``probes.h5``                 :mod:`.probes`          :mod:`railvib_hpc.reconstruct.probes`
``transient.h5``,             :mod:`.transient`       :mod:`railvib_hpc.transient.stage`,
``transient_checkpoint.h5``                           :mod:`railvib_hpc.transient.output`
============================  ======================  =====================================

Each module's docstring is the file's layout; its ``check_<file>`` is the data check
(:data:`railvib_hpc.io.stage_checks.CHECKS`), on write and on reuse. A writer that takes
a model object of a higher layer (the mesh, the DOF map, a stage's streams) lives with
that stage, and the module names it. :mod:`.checks` has what the checks share.
"""
