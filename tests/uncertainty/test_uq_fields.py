"""Random fields on element centres: mean, variance and correlation length within their
sampling error, independence of the partition, and the element kernels scaled through the
problem object."""

from __future__ import annotations

import numpy as np
import pytest
from fem_tools import box_mesh

from railvib_hpc.config import Case
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.model.elements import element_batches
from railvib_hpc.problem import Problem
from railvib_hpc.schema import PART_ID
from railvib_hpc.uncertainty.fields import RandomField, correlation, resolution_warnings

LAYERS = [{"thickness": 2.0, "c_s": 150.0, "nu": 0.3, "rho": 1800.0},
          {"thickness": 0.0, "c_s": 250.0, "nu": 0.3, "rho": 1900.0}]


def _centres(n: int, h: float) -> np.ndarray:
    """Centres of a structured n x n x 4 grid of elements of size h (x fastest)."""
    g = (np.arange(n) + 0.5) * h
    z = (np.arange(4) + 0.5) * h
    Z, Y, X = np.meshgrid(z, g, g, indexing="ij")
    return np.column_stack([X.ravel(), Y.ravel(), Z.ravel()]), n


@pytest.mark.parametrize("model", ["gaussian", "exponential", "matern"])
def test_field_reproduces_mean_variance_and_correlation_length(model):
    h, length = 0.5, 3.0
    pts, n = _centres(32, h)
    reals = 16
    g = np.array([RandomField("soil_layer_1", "E", model, 0.25, length, 1.0, 1.5,
                              seed=100 + r).gaussian(pts) for r in range(reals)])
    # the standard Gaussian field: mean 0, variance 1 (over space and realisations; the
    # standard error of the mean with ~(L/l)^2 independent patches per realisation)
    patches = reals * (n * h / length) ** 2
    assert abs(g.mean()) < 4 / np.sqrt(patches)
    assert g.var() == pytest.approx(1.0, abs=4 * np.sqrt(2 / patches))
    # correlation along x at lags of 1 to 8 elements against the model's
    grid = g.reshape(reals, 4, n, n)
    for lag in (2, 4, 6, 8):
        emp = (grid[..., :-lag] * grid[..., lag:]).mean() / grid.var()
        assert emp == pytest.approx(float(correlation(model, np.array(lag * h), length, 1.5)),
                                    abs=0.1)
    # the lognormal factor: mean 1, coefficient of variation 0.25 (same error bound)
    f = RandomField("soil_layer_1", "E", model, 0.25, length, 1.0, 1.5, 100).factors(pts)
    assert np.allclose(np.log(f), np.sqrt(np.log1p(0.25**2)) * g[0] - np.log1p(0.25**2) / 2)
    s = np.sqrt(np.log1p(0.25**2))
    factors = np.exp(s * g - s * s / 2)
    assert abs(factors.mean() - 1.0) < 4 * 0.25 / np.sqrt(patches)
    assert factors.std() / factors.mean() == pytest.approx(0.25, rel=0.15)


def test_field_values_do_not_depend_on_the_partition():
    pts, _ = _centres(10, 1.0)
    f = RandomField("soil_layer_1", "E", "exponential", 0.3, 4.0, 1.0, 1.5, seed=5)
    whole = f.factors(pts)
    halves = np.concatenate([f.factors(pts[::2]), f.factors(pts[1::2])])
    order = np.concatenate([np.arange(len(pts))[::2], np.arange(len(pts))[1::2]])
    assert np.allclose(halves, whole[order], rtol=1e-12)
    assert not np.allclose(whole, RandomField(*list(f.__dict__.values())[:-1], 6).factors(pts))


def test_short_correlation_lengths_warn_with_the_numbers():
    f = RandomField("soil_layer_2", "rho", "gaussian", 0.1, 0.4, 2.0, 1.5, 0)
    (w,) = resolution_warnings([f], {"soil_layer_2": (0.8, 0.5)})
    assert "horizontal correlation length of 0.4 m" in w and "0.8 m" in w
    assert resolution_warnings([f], {"soil_layer_2": (0.3, 0.5)}) == []


def test_problem_carries_the_fields_into_the_element_kernels():
    base = Case.defaults().replace({"soil.layers": LAYERS, "uncertainty.field": [
        {"layer": 1, "quantity": "E", "model": "gaussian", "cov": 0.3, "len_h": 2.0,
         "len_v": 1.0}, {"layer": 1, "quantity": "rho", "model": "exponential", "cov": 0.1,
                         "len_h": 2.0, "len_v": 1.0}]})
    nominal = Problem.from_case(base)
    assert nominal.fields == ()                      # realisation 0: the nominal layers
    problem = Problem.from_case(base.replace({"uncertainty.realisation": 3}))
    assert [f.quantity for f in problem.fields] == ["E", "rho"]
    assert len({f.seed for f in problem.fields}) == 2
    points, hexes = box_mesh(4, 3, 2, 4.0, 3.0, 1.0)
    mesh = Mesh(points, hexes, np.full(len(hexes), PART_ID["soil_layer_1"]),
                np.zeros((0, 2), int), np.zeros(0, int))
    (b0,) = list(element_batches(mesh, nominal))
    (b1,) = list(element_batches(mesh, problem))
    centres = points[hexes].mean(axis=1)
    fe = problem.fields[0].factors(centres)
    fr = problem.fields[1].factors(centres)
    assert np.allclose(b1.K, b0.K * fe[:, None, None])
    assert np.allclose(b1.M, b0.M * fr[:, None, None])
    assert np.ptp(fe) > 0.05


def test_a_field_realisation_is_an_input_of_the_modes_not_of_a_run_without_fields():
    from railvib_hpc.io.products import inputs_hash

    base = Case.defaults().replace({"soil.layers": LAYERS})
    assert inputs_hash(base, "modes.h5") == inputs_hash(Case.defaults().replace(
        {"soil.layers": LAYERS, "uncertainty.samples": 64}), "modes.h5")
    field = [{"layer": 1, "quantity": "E", "model": "gaussian", "cov": 0.3, "len_h": 2.0,
              "len_v": 1.0}]
    one = base.replace({"uncertainty.field": field, "uncertainty.realisation": 1})
    two = base.replace({"uncertainty.field": field, "uncertainty.realisation": 2})
    digests = {inputs_hash(c, name) for c in (one, two) for name in ("modes.h5",)}
    assert len(digests) == 2 and inputs_hash(base, "modes.h5") not in digests
    assert inputs_hash(one, "mbs.h5") != inputs_hash(two, "mbs.h5")
    assert inputs_hash(one, "transient.h5") != inputs_hash(two, "transient.h5")
