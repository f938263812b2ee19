"""The data check of each stage file (:data:`CHECKS`): finite values and plausibility
against the model's sizes and the case's loads, on write and on reuse.

Each file format has one home in :mod:`railvib_hpc.io.formats`, with its layout, its check
(``check_<file>(path, full, context)``: a list of problems, empty when sound; ``full``
False when the content is vouched for by its record) and, where they sit in the io layer,
its writer and reader; :mod:`railvib_hpc.io.formats.checks` has what the checks share.
Each stage module names the check of each of its products (the ``check`` of its
:class:`~railvib_hpc.io.products.StageFile` rows); declaring a row
(:func:`~railvib_hpc.io.products.declare`) adds its check to this table.
"""

from __future__ import annotations

from collections.abc import Callable

#: The data check of each stage file (by table name), filled as the rows are declared.
CHECKS: dict[str, Callable] = {}
