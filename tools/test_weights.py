"""Record how long each test takes, for the order in which pytest-xdist hands out the files.

The one-rank passes run in NP pytest-xdist workers, a file at a time (``--dist loadfile``,
so a module's fixtures are built once). A file that comes late and runs long keeps one
worker busy while the others are idle: the 2026-12-06 slow pass took 652 s for about
1,150 s of work on 2 workers. ``tests/conftest.py`` therefore sorts the test files by
the seconds recorded here of their selected tests, the longest first (the
longest-processing-time rule), and the
Makefile turns off xdist's own reordering by test count (``--no-loadscope-reorder``).
Only the order depends on these numbers: a test missing here (a new one) counts 0 s, and
stale numbers make a pass slower, never wrong.

Usage: run a pass with ``PYTEST_ARGS=--durations=0`` and feed its output::

    make test-slow PYTEST_ARGS=--durations=0 2>&1 | tee slow.log
    python tools/test_weights.py slow.log [quick.log ...]     # writes tests/data/

Lines ``<seconds>s <phase> <test id>`` (pytest's durations report) are summed per test
(setup, call, teardown; a line that every rank of mpirun printed counts once); a test in
several logs keeps its largest sum.
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WEIGHTS = ROOT / "tests" / "data" / "test_weights.json"
#: pytest's ``--durations`` lines: seconds, phase, test id.
LINE = re.compile(r"^\s*([0-9.]+)s (call|setup|teardown)\s+(tests/\S+)")


def weights(texts: list[str]) -> dict[str, float]:
    """Seconds per test id: summed over each text's phases, the largest over the texts.

    >>> weights(["1.5s call tests/a.py::t\\n2.0s setup tests/a.py::t\\n3.0s call tests/b.py::v",
    ...          "4.0s call tests/b.py::v"])
    {'tests/a.py::t': 3.5, 'tests/b.py::v': 4.0}
    """
    out: dict[str, float] = {}
    for text in texts:
        phases: dict[tuple[str, str], float] = {}     # (every rank of mpirun prints its own)
        for line in text.splitlines():
            m = LINE.match(line)
            if m:
                key = (m.group(3), m.group(2))
                phases[key] = max(phases.get(key, 0.0), float(m.group(1)))
        sums: dict[str, float] = {}
        for (test, _), sec in phases.items():
            sums[test] = sums.get(test, 0.0) + sec
        for test, sec in sums.items():
            out[test] = round(max(out.get(test, 0.0), sec), 2)
    return dict(sorted(out.items()))


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.strip().splitlines()[0] + "\nusage: python tools/test_weights.py LOG...",
              file=sys.stderr)
        return 2
    w = weights([Path(a).read_text(errors="replace") for a in argv])
    WEIGHTS.write_text(json.dumps(w, indent=1) + "\n")
    print(f"wrote {WEIGHTS.relative_to(ROOT)}: {len(w)} tests, {sum(w.values()):.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
