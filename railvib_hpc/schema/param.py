"""The :class:`Param` of one case-file key, the sources its defaults cite (the thesis's
APDL script and tables) and the builders of the keys many sections share (a material's
four keys, an APDL coordinate).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from ..applies import Condition


@dataclass(frozen=True)
class Param:
    """One case-file key.

    Parameters
    ----------
    default
        Default value (the thesis's APDL value where one exists).
    kind
        ``"float"``, ``"int"``, ``"str"``, ``"bool"``, ``"floats"`` (list of
        numbers), ``"ints"`` (list of integers), ``"bools"`` (list of true/false),
        ``"strs"`` (list of strings) or ``"triples"`` (list of ``[a, b, c]`` numbers).
    unit
        SI unit, ``"-"`` for dimensionless.
    doc
        One-line meaning (shown in the README reference and in errors).
    check
        ``"pos"`` (> 0), ``"nonneg"`` (>= 0), ``"poisson"`` (0 <= nu < 0.5),
        ``"fraction"`` (0 <= x < 1), ``"unit"`` (0 <= x <= 1), ``"refinement"`` (0 < x <= 6),
        ``"angle"`` (``|x| <=`` :data:`MAX_ROTATION_DEG`), ``"name"`` (letters, digits and
        ``_.+-``) or ``None``; applied to every entry of a list.
    choices
        Allowed values for strings (or list items).
    unique
        Lists only: at least one entry, all distinct.
    maximum
        Largest allowed value (numbers; ``None``: no bound beyond ``check``); its reason
        belongs in ``doc``.
    source
        Where the default comes from (the thesis's APDL script, its tables, the literature),
        shown in the case reference; ``""`` for the numerical settings of this program
        (solver tolerances, output steps...). A preset's values carry their own
        (:data:`PRESET_SOURCES`).
    derived
        How the value follows from other keys when the case does not give it (``""``: it
        does not; :func:`railvib_hpc.site.derive_keys` computes it; a given value must
        agree). The baseline case lists such a key commented out.
    applies
        The condition under which the key's feature is on (:mod:`railvib_hpc.applies`;
        ``None``: always). Where it does not hold, the key must keep its default (the
        preset's value): :func:`railvib_hpc.validation.feature_key_problems` refuses any
        other with "applies to ... only", the one rule every key obeys.
    """

    default: Any
    kind: str
    unit: str
    doc: str
    check: str | None = None
    choices: tuple[str, ...] = field(default_factory=tuple)
    unique: bool = False
    maximum: float | None = None
    source: str = ""
    derived: str = ""
    applies: Condition | None = None


_APDL = "thesis App. A (APDL)"
_T1 = "thesis Table I"
_T2 = "thesis Table II"
_RAIL_SEC = "App. A SECTYPE,1,BEAM,I / SECDATA,0.1524,0.07,0.19,0.0165,0.045,0.0175"
_SLP_SEC = "App. A SECTYPE,2,BEAM,QUAD / SECDATA,-0.135,-0.11,.135,-.11,.090,.11,-.090,.11"
_MANCHESTER = "Manchester Benchmark vehicle 1 (Iwnicki, Veh. Syst. Dyn. 30 (1998) 295-313)"
#: The modal damping of the thesis, the source of every material's damping ratio.
_THESIS_DAMPING = "thesis §2.1: 3 % modal damping"
_OTHER_DAMPING = "not in the thesis: the 3 % of the other materials"


def _mat(e: float, nu: float, rho: float, what: str, source: str | tuple[str, str, str],
         damping_source: str = _THESIS_DAMPING, applies: Condition | None = None
         ) -> dict[str, Param]:
    """``materials.<name>``: ``source`` of E, nu and rho (one for all three, or each its
    own); ``applies``: when the material is in the model (all four keys)."""
    e_src, nu_src, rho_src = (source,) * 3 if isinstance(source, str) else source
    return {
        "E": Param(e, "float", "Pa", f"Young's modulus of the {what}", "pos", source=e_src,
                   applies=applies),
        "nu": Param(nu, "float", "-", f"Poisson's ratio of the {what}", "poisson",
                    source=nu_src, applies=applies),
        "rho": Param(rho, "float", "kg/m^3", f"density of the {what}", "pos", source=rho_src,
                     applies=applies),
        "damping_ratio": Param(0.03, "float", "-",
                               f"damping ratio of the {what}, used when modal.damping = "
                               "'strain_energy'", "fraction", source=damping_source,
                               applies=applies),
    }


def _mp(number: int, ex: str, prxy: str, dens: str) -> tuple[str, str, str]:
    """The sources of E, nu and rho of APDL material ``number``: its MP commands, as written."""
    return (f"{_APDL}: MP,EX,{number},{ex}", f"{_APDL}: MP,PRXY,{number},{prxy}",
            f"{_APDL}: MP,DENS,{number},{dens}")


def _apdl_coordinate(name: str, value: float, what: str,
                     applies: Condition | None = None) -> Param:
    """``geometry.<name>``: the APDL script's coordinate ``name`` (cited with its value)."""
    return Param(value, "float", "m", f"{name}: {what}", source=f"{_APDL}: {name}={value:g}",
                 applies=applies)


