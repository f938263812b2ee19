"""Check a case: every value against the schema, then the whole case for consistency.

Every check appends ``(key, value, what is allowed)`` problems to a list instead of
raising, so that :func:`railvib_hpc.config.build_case` reports them all in one
:class:`~railvib_hpc.errors.CaseError`. The geometry the cross-key checks measure
(embankment toe, the building's turned plan and twist, slab levels) is
:mod:`railvib_hpc.site`'s.

The checks live in one module per kind: :mod:`.values` (one value against its schema
entry), :mod:`.features` (the rule of :attr:`~railvib_hpc.schema.Param.applies`),
:mod:`.track`, :mod:`.layout` and :mod:`.dynamics` (the cross-key checks of the track and
its loads, of the site's layout, of the solution) and :mod:`.consistency` (the whole case,
the studies' tables and a command's refusals). Every public name is importable from
``railvib_hpc.validation``.

Examples
--------
>>> from railvib_hpc.config import Case
>>> from railvib_hpc.validation import check_consistency, feature_key_problems
>>> check_consistency(Case.defaults()), feature_key_problems(Case.defaults())
([], [])
"""

from __future__ import annotations

from .consistency import check_consistency, check_studies, command_problems
from .features import feature_key_problems, switched_off
from .values import ALL_KEYS, SOIL_LAYER_DAMPING_RATIO, check_value

__all__ = [
    "ALL_KEYS",
    "SOIL_LAYER_DAMPING_RATIO",
    "check_consistency",
    "check_studies",
    "check_value",
    "command_problems",
    "feature_key_problems",
    "switched_off",
]
