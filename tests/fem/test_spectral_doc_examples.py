"""The docstring examples of the GLL dispersion modules and the order advice (seconds each:
Bloch eigenproblems and root searches, so in their own file rather than in
``tests/test_docs_examples.py``, which runs the cheap modules' examples)."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = [
    "railvib_hpc.fem.dispersion_gll",
    "railvib_hpc.fem.dispersion_gll_rayleigh",
    "railvib_hpc.fem.spectral_advice",
]


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    result = doctest.testmod(importlib.import_module(name), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
