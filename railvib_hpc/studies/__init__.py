"""Studies: mesh convergence, modal truncation, boundary reflection and speed sweep.

Each study is one command, ``railvib study KIND CASE.toml``, that runs its variants
(:mod:`.common`: one folder per variant, stage files reused, a ``result.json`` per finished
variant so an interrupted study resumes), merges them into ``report.md``, ``report.json``
and PNG figures (:mod:`.report`) and prints a verdict:

* :mod:`.convergence` — refinement levels, Richardson extrapolation (:mod:`.richardson`),
  "converged within X %";
* :mod:`.modes` — number of modes with/without the static correction, modes needed for a
  given accuracy;
* :mod:`.reflection` — soil domains of growing size, do boundary reflections matter;
* :mod:`.speed` — speeds on the same modes, peak response and contact force per speed.

Study settings: :mod:`.settings` (defaults, ``--study-set key=value``).
"""

from .runner import STUDY_MODULES, execute_study
from .settings import SETTINGS, StudySettingsError, study_settings

__all__ = ["SETTINGS", "STUDY_MODULES", "StudySettingsError", "execute_study",
           "study_settings"]
