"""The problem object (railvib_hpc/problem.py): what it reads from a case, and that it is frozen."""

from __future__ import annotations

import dataclasses
import math

import pytest

from railvib_hpc.config import Case
from railvib_hpc.problem import Problem
from railvib_hpc.schema import BOUNDARY_FACES, INTERFACE_PARTS

#: Two soil layers, the first given by its shear-wave speed (E = 2 rho c_s^2 (1 + nu)).
LAYERS = [{"thickness": 2.0, "c_s": 150.0, "nu": 0.3, "rho": 1800.0, "damping_ratio": 0.05},
          {"thickness": 0.0, "E": 4e8, "nu": 0.25, "rho": 2000.0}]


def test_every_value_is_the_case_s():
    case = Case.defaults().replace({"boundary.y_min": "absorbing", "damping.pads": True,
                                    "usp.modulus": 1e8, "modal.lumped_mass": True})
    problem = Problem.from_case(case)
    for name, values in case["materials"].items():
        assert dataclasses.asdict(problem.material(name)) == values
    for name, values in case["sections"].items():
        assert dataclasses.asdict(problem.sections[name]) == values
    assert dataclasses.asdict(problem.pads) == case["pads"]
    assert dict(problem.boundary.faces) == {f: case[f"boundary.{f}"] for f in BOUNDARY_FACES}
    assert problem.boundary.faces["y_min"] == "absorbing"
    for kind in INTERFACE_PARTS:
        got = problem.interfaces[kind]
        assert (got.modulus, got.shear_ratio, got.loss_factor) == (
            case[f"{kind}.modulus"], case[f"{kind}.shear_ratio"], case[f"{kind}.loss_factor"])
        assert got.width == (case["usp.width"] if kind == "usp" else 0.0)
    assert dataclasses.asdict(problem.damping) == {
        **case["damping"], "ratio": case["modal.damping_ratio"]}
    assert problem.lumped_mass is True and problem.hex_formulation == case["modal.hex_formulation"]


def test_soil_layers_are_materials_with_e_from_the_shear_wave_speed():
    problem = Problem.from_case(Case.defaults().replace({"geometry.z0": 0.0,
                                                         "soil.layers": LAYERS}))
    top = problem.material("soil_layer_1")
    e_from_c_s = 2 * 1800.0 * 150.0**2 * 1.3
    young = top.E
    assert young == pytest.approx(e_from_c_s, rel=1e-12)
    assert math.sqrt(top.E / (2 * (1 + top.nu) * top.rho)) == pytest.approx(150.0, rel=1e-12)
    assert top.damping_ratio == 0.05
    assert problem.material("soil_layer_2").E == 4e8
    with pytest.raises(KeyError, match="soil_layer_3: the case gives 2 soil layer"):
        problem.material("soil_layer_3")


def test_the_problem_is_frozen():
    problem = Problem.from_case(Case.defaults())
    with pytest.raises(dataclasses.FrozenInstanceError):
        problem.lumped_mass = True
    with pytest.raises(dataclasses.FrozenInstanceError):
        problem.material("subgrade").E = 1.0
    with pytest.raises(TypeError):
        problem.materials["subgrade"] = problem.material("ballast")
    with pytest.raises(TypeError):
        problem.boundary.faces["base"] = "free"
