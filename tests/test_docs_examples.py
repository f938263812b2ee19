"""Docstring examples are tests (the modules whose examples are cheap enough to run)."""

from __future__ import annotations

import doctest

import pytest

import railvib_hpc.sections


@pytest.mark.parametrize("module", [railvib_hpc.sections])
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0
