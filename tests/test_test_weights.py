"""tools/test_weights.py: the seconds per test that order the one-rank passes' files."""

from __future__ import annotations

import doctest
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))
import test_weights  # noqa: E402


def test_the_examples_hold():
    assert doctest.testmod(test_weights).failed == 0


def test_a_line_every_rank_printed_counts_once_and_phases_add_up():
    log = "\n".join(["3.00s call     tests/x.py::t[P]", "3.00s call     tests/x.py::t[P]",
                     "1.50s setup    tests/x.py::t[P]", "0.20s teardown tests/y.py::u",
                     "noise 9.0s call tests/z.py::v"])
    assert test_weights.weights([log]) == {"tests/x.py::t[P]": 4.5, "tests/y.py::u": 0.2}


def test_the_recorded_weights_name_existing_test_files():
    """A renamed or deleted file leaves its weight behind: regenerate (the module notes)."""
    seconds = json.loads(test_weights.WEIGHTS.read_text())
    assert seconds and all(v >= 0 for v in seconds.values())
    missing = {k.split("::")[0] for k in seconds} - {
        str(p.relative_to(ROOT)) for p in (ROOT / "tests").rglob("test_*.py")}
    assert not missing, missing
