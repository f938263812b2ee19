"""The case as the layers below :mod:`railvib_hpc.config` read it: :class:`CaseView`, the
interface of :class:`railvib_hpc.config.Case` that the site geometry, the uncertain inputs
and the validation take (duck-typed, so they never import the case module).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol


class CaseView(Protocol):
    """A case indexed by dotted schema keys (``case["geometry.x1"]``).

    Attributes
    ----------
    given
        The entries the file, the dict and the overrides gave (dotted keys), ``None`` where
        not known.
    """

    given: dict[str, Any] | None

    def __getitem__(self, dotted: str) -> Any:
        """The value of a dotted key (a section for a section's name)."""

    def __contains__(self, dotted: object) -> bool:
        """Whether the dotted key is in the case."""

    def get(self, dotted: str, default: Any = None) -> Any:
        """The value of a dotted key, ``default`` where it is not in the case."""

    def resolve(self, relative: str) -> Path:
        """A path of the case (``mesh.file``, ``irregularity.file``) against its folder."""
