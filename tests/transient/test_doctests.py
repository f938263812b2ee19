"""The docstring examples of the transient-related modules are tests."""

from __future__ import annotations

import doctest
import importlib

import pytest


@pytest.mark.parametrize("module", ["railvib_hpc.transient.scheme", "railvib_hpc.fem.boundary",
                                    "railvib_hpc.model.damping", "railvib_hpc.fem.halfspace"])
def test_docstring_examples(module):
    result = doctest.testmod(importlib.import_module(module))
    assert result.attempted > 0 and result.failed == 0
