"""Random fields of a soil layer's stiffness or density on the element centres (GSTools).

A field multiplies the layer's Young's modulus (``quantity = "E"``) or density
(``"rho"``) element by element by a lognormal factor of mean 1 and coefficient of
variation ``cov``: ``exp(s g - s^2/2)`` with ``s^2 = ln(1 + cov^2)``, ``g`` a standard
Gaussian field with the covariance model (GSTools ``Gaussian``, ``Exponential`` or
``Matern`` with smoothness ``nu``), the horizontal correlation length ``len_h`` along x
and y and the vertical ``len_v`` along z (GSTools's ``len_scale``, anisotropic; for the
Gaussian and exponential models the integral scale). GSTools's randomisation method
draws the spectral modes from the seed and evaluates them point by point: the factor of
an element depends only on its centre and the seed, so every rank computes the same
value for its own elements and the field does not depend on the partition.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: The covariance models.
MODELS = ("gaussian", "exponential", "matern")
#: The quantities a field varies.
QUANTITIES = ("E", "rho")
#: Fourier modes of GSTools's randomisation method (its default, 1000: the variance of
#: the field is reproduced to about 1 %, Hesse et al. 2014).
MODE_NUMBER = 1000


@dataclass(frozen=True)
class RandomField:
    """One random field of a material.

    Attributes
    ----------
    part
        The material it varies (``soil_layer_<k>``).
    quantity
        ``E`` or ``rho``.
    model
        One of :data:`MODELS`.
    cov
        Coefficient of variation of the factor.
    len_h, len_v
        Horizontal and vertical correlation lengths [m].
    smoothness
        Matérn's ``nu`` (the other models ignore it).
    seed
        Seed of this realisation.
    """

    part: str
    quantity: str
    model: str
    cov: float
    len_h: float
    len_v: float
    smoothness: float
    seed: int

    def gaussian(self, centres: np.ndarray) -> np.ndarray:
        """The standard Gaussian field at points ``(n, 3)``."""
        import gstools as gs

        cls = {"gaussian": gs.Gaussian, "exponential": gs.Exponential,
               "matern": gs.Matern}[self.model]
        extra = {"nu": self.smoothness} if self.model == "matern" else {}
        model = cls(dim=3, var=1.0, len_scale=[self.len_h, self.len_h, self.len_v], **extra)
        srf = gs.SRF(model, mean=0.0, mode_no=MODE_NUMBER)
        pts = np.asarray(centres, dtype=float)
        if not len(pts):
            return np.zeros(0)
        return np.asarray(srf(pts.T, seed=self.seed, mesh_type="unstructured",
                              store=False), dtype=float)

    def factors(self, centres: np.ndarray) -> np.ndarray:
        """The lognormal factors (mean 1, ``cov``) at points ``(n, 3)``."""
        s = math.sqrt(math.log1p(self.cov ** 2))
        return np.exp(s * self.gaussian(centres) - 0.5 * s * s)


def correlation(model: str, lag: np.ndarray, length: float, smoothness: float = 1.0
                ) -> np.ndarray:
    """The correlation of the Gaussian field at ``lag`` along one axis of length
    ``length`` (GSTools's definition of the model)."""
    import gstools as gs

    cls = {"gaussian": gs.Gaussian, "exponential": gs.Exponential, "matern": gs.Matern}[model]
    extra = {"nu": smoothness} if model == "matern" else {}
    return np.asarray(cls(dim=1, var=1.0, len_scale=length, **extra).correlation(lag))


def element_factors(fields, part: str, quantity: str, centres: np.ndarray) -> np.ndarray:
    """The product of every field of ``part`` and ``quantity`` at ``centres`` (ones when
    none)."""
    out = np.ones(len(centres))
    for f in fields:
        if f.part == part and f.quantity == quantity:
            out *= f.factors(centres)
    return out


def resolution_warnings(fields, element_sizes: dict[str, tuple[float, float]]) -> list[str]:
    """Warnings for fields whose correlation length is below the element size.

    Parameters
    ----------
    fields
        The :class:`RandomField` objects.
    element_sizes
        ``{part: (largest horizontal, largest vertical element size)}`` [m].

    Returns
    -------
    list of str
        One sentence per such field and direction: an element then holds one value of a
        field that varies inside it, so the field is smoothed to the mesh.
    """
    out = []
    for f in fields:
        if f.part not in element_sizes:
            continue
        h, v = element_sizes[f.part]
        for what, length, size in (("horizontal", f.len_h, h), ("vertical", f.len_v, v)):
            if length < size:
                out.append(f"the random field of {f.part}.{f.quantity} has a {what} "
                           f"correlation length of {length:g} m, below its elements' "
                           f"{what} size of up to {size:.3g} m: the elements average it "
                           "(refine the layer or lengthen the correlation)")
    return out
