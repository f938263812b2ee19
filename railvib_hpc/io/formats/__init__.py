"""The file formats of an output folder: one module each, with its layout, writer, reader and
check.

============================  ======================  =====================================
file                          module                  writer and reader
============================  ======================  =====================================
``mesh.h5``, ``mesh.xdmf``    :mod:`.mesh`            here (the reader gives the arrays:
                                                      :mod:`railvib_hpc.mesh.mesh_io` makes
                                                      the mesh model of them)
``modes.h5``, ``modes.xdmf``  :mod:`.modes`           here
``static.h5``                 :mod:`.static`          here (of arrays: :mod:`railvib_hpc.modal.
                                                      static` forms them from the DOF map)
``modal_damping.h5``          :mod:`.modal_damping`   here
``bands/`` (the band cache)   :mod:`.bands`           here
``mbs.h5``                    :mod:`.mbs`             here (of the passage duck-typed; one
                                                      reader, :class:`.mbs.MbsFile`)
``fields.h5``,                :mod:`.fields`          here (layout, XDMF, reader); the
``fields.xdmf``                                       blocks are streamed by :mod:`railvib_hpc.
                                                      reconstruct.fields` and :mod:`railvib_hpc.
                                                      transient.output`
``probes.h5``, ``probes/``    :mod:`.probes`          here
``transient.h5``,             :mod:`.transient`       here (of arrays: :mod:`railvib_hpc.
``transient_checkpoint.h5``                           transient.stage` forms them; one reader
                                                      of ``transient.h5``,
                                                      :class:`.transient.TransientFile`)
============================  ======================  =====================================

Each module's docstring is the file's layout; its ``check_<file>`` is the data check
(:data:`railvib_hpc.io.stage_checks.CHECKS`), on write and on reuse. A writer here takes
plain arrays, or a model object of a higher layer duck-typed (the mesh: its type is named
under ``TYPE_CHECKING`` only, so the io layer imports nothing above it); a reader gives
arrays, of which the stage builds its model objects (``mesh.h5``). :mod:`.checks` has
what the checks and readers share.
"""
