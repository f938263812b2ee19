"""The eigensolve's progress lines before the first mode converges: an honest ETA."""

from __future__ import annotations

import io

from railvib_hpc.log import Reporter
from railvib_hpc.modal.stage import EigenProgress


def test_no_eta_before_the_first_mode_converges():
    """With 0 of 20 modes converged there is no rate to extrapolate: ``ETA --``, not
    ``ETA nan s``; once modes converge, the ETA is a number of seconds."""
    stream = io.StringIO()
    progress = EigenProgress(Reporter(0, stream))
    progress(0, 20, 40)
    first = stream.getvalue().splitlines()[-1]
    assert "0/20 modes converged" in first and "ETA     --" in first
    assert "nan" not in first
    progress.last = -1e9                  # the next line is due at once
    progress(5, 20, 40)
    second = stream.getvalue().splitlines()[-1]
    assert "25.0 %" in second and second.rstrip().endswith(" s") and "nan" not in second
