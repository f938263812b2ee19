"""The vibration standards the assessment knows, declared below the case schema: their
names, titles and the histories they assess, and the building uses, periods and event
frequencies that select their limits.

The case schema takes its choices from here (``assessment.standards``, ``building_use``,
``period``, ``fta_events``); :mod:`railvib_hpc.assess.standards` registers each declared
standard's evaluation under its name (:func:`railvib_hpc.assess.standards.standard`), in
the order declared here, which is the report's order. A new standard is one declaration
here and one decorated evaluation there.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class StandardDeclaration:
    """One vibration standard as the case schema and the reports name it.

    Attributes
    ----------
    name
        The name used in case files (``assessment.standards``) and results.
    title
        Heading of its block in results and reports.
    quantity
        The history it assesses: ``"acceleration"`` or ``"velocity"``.
    comparison_only
        Reported for comparison, never part of the overall verdict.
    """

    name: str
    title: str
    quantity: str
    comparison_only: bool = False


#: The declared standards: name -> :class:`StandardDeclaration`, in report order.
DECLARED_STANDARDS: dict[str, StandardDeclaration] = {s.name: s for s in (
    StandardDeclaration("iso2631", "ISO 2631-2 Wm / ISO 10137 base curve", "acceleration"),
    StandardDeclaration("din4150-2", "DIN 4150-2 (people in buildings)", "velocity"),
    StandardDeclaration("din4150-3", "DIN 4150-3 (structural damage)", "velocity"),
    StandardDeclaration("fta", "FTA (US transit) velocity level", "velocity"),
    StandardDeclaration("vc", "VC curves (one-third-octave velocity)", "velocity"),
    StandardDeclaration("thesis", "Thesis 0.005 g peak (comparison only)", "acceleration",
                        comparison_only=True),
)}

#: What each building use selects in each standard (each overridable by keyword).
BUILDING_USES: dict[str, dict[str, str]] = {
    "critical": {"fta": "sensitive", "vc": "critical", "din4150-3": "residential"},
    "residential": {"fta": "residential", "vc": "residential", "din4150-3": "residential"},
    "office": {"fta": "institutional", "vc": "office", "din4150-3": "residential"},
    "workshop": {"fta": "institutional", "vc": "workshop", "din4150-3": "commercial"},
}
#: The assessment periods (ISO 10137, DIN 4150-2).
PERIODS = ("day", "night")
#: The FTA event frequencies.
FTA_EVENTS = ("frequent", "occasional", "infrequent")
