"""Docstring examples are tests (the modules whose examples are cheap enough to run).

The Python API's examples run the modal and multibody stages of a coarse model (a few
seconds); the module example of :mod:`railvib_hpc.api` is ``examples/pad_stiffness.py``,
which ``tests/test_examples.py`` runs.
"""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "railvib_hpc",
    "railvib_hpc.api",
    "railvib_hpc.applies",
    "railvib_hpc.config",
    "railvib_hpc.site",
    "railvib_hpc.validation",
    "railvib_hpc.pipeline",
    "railvib_hpc.petsc_env",
    "railvib_hpc.sections",
    "railvib_hpc.io.run_record",
    "railvib_hpc.io.digests",
    "railvib_hpc.io.out_folder",
    "railvib_hpc.io.products",
    "railvib_hpc.io.stage_protocol",
    "railvib_hpc.io.stage_outputs",
    "railvib_hpc.reconstruct.probes",
    "railvib_hpc.mesh.turn",
    "railvib_hpc.modal.block_lanczos",
    "railvib_hpc.fem.pml",
    "railvib_hpc.fem.pml_kernel",
    "railvib_hpc.fem.gll",
    "railvib_hpc.fem.spectral_mesh",
    "railvib_hpc.fem.spectral_kernel",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
