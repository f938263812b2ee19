"""Studies: many runs of the pipeline compared, one command each.

Each study is one command, ``railvib study KIND CASE.toml``, that runs its variants
(:mod:`.common`: one folder per variant, stage files reused, a ``result.json`` per finished
variant so an interrupted study resumes), merges them into ``report.md``, ``report.json``
and PNG figures (:mod:`.report`) and prints a verdict. A study is one module that declares
its ``STUDY`` (:class:`.protocol.Study`: name, help line, settings, variants, analysis and
verdict, figures, hooks) and one line of the registry, :data:`.registry.STUDIES`, from
which the command line and :func:`railvib_hpc.api.run_study` take them
(``tests/example_study.py`` is a whole new study). The registered studies:

* :mod:`.convergence` — refinement levels, Richardson extrapolation (:mod:`.richardson`),
  "converged within X %";
* :mod:`.modes` — number of modes with/without the static correction, modes needed for a
  given accuracy;
* :mod:`.reflection` — soil domains of growing size, do boundary reflections matter;
* :mod:`.speed` — speeds on the same modes, peak response and contact force per speed;
* :mod:`.thesis` — the thesis's mode count and band, and the drop of the wheelset, against
  the thesis's numbers;
* :mod:`.mitigation` — the baseline and each measure with everything else identical,
  insertion losses, ranked;
* :mod:`.uncertainty` — the case's uncertain inputs sampled, percentiles, exceedance
  probabilities and Sobol' indices.

Study settings: :mod:`.settings` (defaults, ``--study-set key=value``); the loop over the
variants, the status and the merged report: :mod:`.runner`.
"""

from .protocol import Study
from .registry import STUDIES, STUDY_MODULES, register, study, study_helps
from .runner import execute_study
from .settings import SETTINGS, StudySettingsError, study_settings

__all__ = ["SETTINGS", "STUDIES", "STUDY_MODULES", "Study", "StudySettingsError",
           "execute_study", "register", "study", "study_helps", "study_settings"]
