"""The red team's Case API findings of the fourth round: ``Case.replace`` with two
spellings of one key silently took the last, and ``hash(Case)`` raised TypeError although
the case is documented as frozen."""

from __future__ import annotations

import pytest
from faults import BASELINE

from railvib_hpc.config import Case
from railvib_hpc.errors import CaseError

B = str(BASELINE)


# ------------------------------------------------------------- Case.replace, hash(Case)
def test_conflicting_spellings_are_refused_naming_both():
    """{"vehicle.speed": 20.0, "vehicle": {"speed": 25.0}} gave 25.0."""
    case = Case.from_file(B)
    with pytest.raises(CaseError) as info:
        case.replace({"vehicle.speed": 20.0, "vehicle": {"speed": 25.0}})
    assert str(info.value) == (
        "invalid case file: vehicle.speed = 20.0: given twice with different values, as "
        "'vehicle.speed' = 20.0 and as 'vehicle' -> 'speed' = 25.0: give it once")
    with pytest.raises(CaseError, match="given twice with different values"):
        case.replace({"vehicle.speed": 20.0}, vehicle={"speed": 25.0})
    with pytest.raises(CaseError, match="given twice"):
        Case.from_dict({"vehicle.speed": 20.0, "vehicle": {"speed": 25.0}})
    same = case.replace({"vehicle.speed": 20.0, "vehicle": {"speed": 20}})
    assert same["vehicle.speed"] == 20.0


def test_a_case_hashes_by_its_digest():
    """hash(Case) raised TypeError (unhashable dict)."""
    a, b = Case.from_file(B), Case.from_file(B)
    assert a == b and hash(a) == hash(b)
    c = a.replace({"vehicle.speed": 20.0})
    assert c != a and len({a, b, c}) == 2 and {a: 1}[b] == 1
    assert hash(c) == hash(a.replace({"vehicle.speed": 20.0}))
