"""The ``[uncertainty]`` tables of a case: their entries checked, the keys they vary resolved.

:func:`check_uncertainty_tables` type-checks the lists of tables (the schema kinds
``uncertain_parameters`` and ``random_fields``) and the correlation matrix (kind
``matrix``) as :func:`railvib_hpc.validation.check_value` does for the other kinds;
:func:`check_uncertainty` checks them against the whole case (called by
:func:`railvib_hpc.validation.check_consistency`):

* every ``key`` exists and is a number of the case: a ``float`` key of the schema, or
  ``soil.layers[k].<name>`` of a layer the case gives (its ``c_s`` or ``E``, whichever the
  layer gives, ``nu``, ``rho``, ``damping_ratio``, ``thickness``); unknown keys get a
  did-you-mean;
* each distribution puts at most
  :data:`~railvib_hpc.uncertainty.distributions.PHYSICAL_RANGE_PROBABILITY` outside the
  key's physical range (the range its schema check allows: E > 0, 0 <= nu < 0.5, a
  thickness >= the thinnest layer...); the message gives the probability;
* the correlation matrix is d x d, symmetric with a unit diagonal and positive definite;
  the Sobol' design needs independent inputs (its estimators assume them);
* every field's layer exists.

The case is read duck-typed (``case[key]``), like :mod:`railvib_hpc.site`.
"""

from __future__ import annotations

import difflib
import math
import re
from typing import Any

import numpy as np

from .schema import (
    MAX_ROTATION_DEG,
    MIN_SOIL_LAYER_THICKNESS,
    SOIL_LAYER_KEYS,
    CaseView,
    iter_params,
)
from .uncertainty.distributions import (
    PARAMETER_KEYS,
    PHYSICAL_RANGE_PROBABILITY,
    Marginal,
    make_marginal,
)
from .uncertainty.fields import MODELS, QUANTITIES

#: ``soil.layers[k].<name>``: one entry of a soil layer (1-based k).
LAYER_KEY = re.compile(r"^soil\.layers\[(\d+)\]\.(\w+)$")
#: Keys of one ``[[uncertainty.field]]`` table: (required, meaning).
FIELD_KEYS: dict[str, tuple[bool, str]] = {
    "layer": (True, "the soil layer (1-based, [[soil.layers]] order)"),
    "quantity": (True, "E (stiffness) or rho (density)"),
    "model": (True, "covariance: gaussian, exponential or matern"),
    "cov": (True, "coefficient of variation of the factor (> 0)"),
    "len_h": (True, "horizontal correlation length in m (> 0)"),
    "len_v": (True, "vertical correlation length in m (> 0)"),
    "nu": (False, "Matern smoothness (> 0; default 1.5)"),
}
#: Matérn smoothness of a field that gives none (once mean-square differentiable).
DEFAULT_MATERN_NU = 1.5
#: The physical range of each schema check: (lowest, highest) allowed (None: unbounded).
_RANGES = {"pos": (0.0, None), "nonneg": (0.0, None), "poisson": (0.0, 0.5),
           "fraction": (0.0, 1.0), "unit": (0.0, 1.0), "refinement": (0.0, 6.0),
           "angle": (-MAX_ROTATION_DEG, MAX_ROTATION_DEG)}
_LAYER_RANGES = {"thickness": (MIN_SOIL_LAYER_THICKNESS, None), "nu": (0.0, 0.5),
                 "damping_ratio": (0.0, 1.0)}
#: Sections whose keys change the mesh (a reduced model keeps the nominal mesh).
MESH_SECTIONS = ("geometry", "track", "building", "mesh", "domain", "site", "trench", "wib")
_FLOAT_KEYS = {k: p for k, p in iter_params() if p.kind == "float"}


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


def check_uncertainty_tables(key: str, kind: str, value: Any, problems: list) -> Any:
    """Type checks of ``uncertainty.parameter``, ``uncertainty.field`` (lists of tables)
    and ``uncertainty.correlation`` (a list of rows of numbers); returns the value."""
    if kind == "matrix":
        if not isinstance(value, list) or not all(
                isinstance(r, list) and all(map(_number, r)) for r in value):
            problems.append((key, value, "expected a matrix: a list of rows of numbers, "
                             "e.g. [[1, 0.5], [0.5, 1]]"))
            return value
        return [[float(x) for x in r] for r in value]
    allowed = PARAMETER_KEYS if kind == "uncertain_parameters" else tuple(FIELD_KEYS)
    table = "[[uncertainty.parameter]]" if kind == "uncertain_parameters" else \
        "[[uncertainty.field]]"
    if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
        problems.append((key, value, f"expected a list of tables ({table} with "
                         + ", ".join(allowed) + ")"))
        return value
    for k, entry in enumerate(value):
        unknown = sorted(set(entry) - set(allowed))
        if unknown:
            problems.append((f"{key}[{k + 1}].{unknown[0]}", entry[unknown[0]],
                             "unknown key; allowed: " + ", ".join(allowed)))
    return value


def resolve_key(case: CaseView, key: Any) -> tuple[float | None, tuple, str | None]:
    """The nominal value and physical range of an uncertain ``key``.

    Returns
    -------
    tuple
        ``(nominal, (low, high), problem)``: ``problem`` is None when the key is a number
        of the case, else what is wrong (with a did-you-mean).
    """
    if not isinstance(key, str):
        return None, (None, None), "expected a case key (a string)"
    m = LAYER_KEY.match(key)
    if m:
        k, name = int(m.group(1)), m.group(2)
        layers = case["soil.layers"]
        if not 1 <= k <= len(layers):
            return None, (None, None), (f"the case gives {len(layers)} soil layer(s) "
                                        f"(soil.layers[1]..[{len(layers)}])")
        entry = layers[k - 1]
        if name not in SOIL_LAYER_KEYS or name not in entry:
            have = [n for n in SOIL_LAYER_KEYS if n in entry]
            close = difflib.get_close_matches(name, have, n=1, cutoff=0.5)
            hint = f"; did you mean 'soil.layers[{k}].{close[0]}'?" if close else ""
            return None, (None, None), ("not a number the layer gives; it gives: "
                                        + ", ".join(have) + hint)
        if name == "thickness" and k == len(layers) and float(entry[name]) == 0:
            return None, (None, None), ("the last layer's thickness is 0 (down to the "
                                        "base): it is not a number to vary")
        return float(entry[name]), _LAYER_RANGES.get(name, (0.0, None)), None
    if key in _FLOAT_KEYS:
        p = _FLOAT_KEYS[key]
        low, high = _RANGES.get(p.check, (None, None))
        if p.maximum is not None:
            high = p.maximum if high is None else min(high, p.maximum)
        return float(case[key]), (low, high), None
    close = difflib.get_close_matches(key, list(_FLOAT_KEYS), n=1, cutoff=0.6)
    hint = f"; did you mean '{close[0]}'?" if close else ""
    if key in dict(iter_params()):
        return None, (None, None), "not a real-number key (integers, switches and names " \
            "cannot be uncertain)"
    return None, (None, None), ("unknown key (a numeric case key, or soil.layers[k].c_s, "
                                ".E, .nu, .rho, .damping_ratio, .thickness)" + hint)


def marginals(case: CaseView, problems: list | None = None) -> list[Marginal]:
    """The marginal distributions of ``uncertainty.parameter`` (problems appended)."""
    problems = [] if problems is None else problems
    out = []
    for k, entry in enumerate(case["uncertainty.parameter"]):
        where = f"uncertainty.parameter[{k + 1}]"
        nominal, (low, high), wrong = resolve_key(case, entry.get("key"))
        if wrong:
            problems.append((f"{where}.key", entry.get("key"), wrong))
            continue
        m = make_marginal(where, entry, nominal, problems)
        if m is None:
            continue
        outside = m.mass_outside(low, high)
        if outside > PHYSICAL_RANGE_PROBABILITY:
            rng = " and ".join(x for x in (None if low is None else f"above {low:g}",
                                           None if high is None else f"below {high:g}") if x)
            problems.append((f"{where}.distribution", m.distribution,
                             f"puts probability {outside:.3g} outside the physical range of "
                             f"{m.key} ({rng}; at most {PHYSICAL_RANGE_PROBABILITY:g} "
                             "allowed): use a lognormal or truncated_normal distribution, "
                             "or a smaller spread"))
            continue
        out.append(m)
    return out


def check_uncertainty(case: CaseView) -> list[tuple[str, Any, str]]:
    """The cross-key checks of ``[uncertainty]`` (see the module notes)."""
    out: list[tuple[str, Any, str]] = []
    params = case["uncertainty.parameter"]
    found = marginals(case, out)
    keys = [e.get("key") for e in params]
    dup = sorted({k for k in keys if isinstance(k, str) and keys.count(k) > 1})
    if dup:
        out.append(("uncertainty.parameter", dup, "each key may be uncertain once"))
    names = [m.name for m in found]
    if len(set(names)) != len(names):
        out.append(("uncertainty.parameter", names, "the parameters' names must be distinct"))
    corr = case["uncertainty.correlation"]
    if corr:
        out.extend(_check_correlation(corr, len(params), case["uncertainty.method"]))
    if case["uncertainty.method"] == "sobol":
        n = case["uncertainty.samples"]
        if not params and case["uncertainty.field"]:
            out.append(("uncertainty.method", "sobol", "Sobol' indices need at least one "
                        "[[uncertainty.parameter]] (a random field is not an input of the "
                        "design): use method = 'lhs' or 'mc'"))
        if n & (n - 1):
            out.append(("uncertainty.samples", n, "the sobol method needs a power of 2 "
                        f"(e.g. {1 << max(n - 1, 1).bit_length()})"))
    if case["uncertainty.model"] == "reduced":
        for k, key in enumerate(keys):
            if isinstance(key, str) and (key.endswith(".thickness")
                                         or key.split(".")[0] in MESH_SECTIONS):
                out.append((f"uncertainty.parameter[{k + 1}].key", key,
                            "changes the mesh, which the reduced model (uncertainty.model = "
                            "'reduced') keeps at the nominal one: use model = 'full'"))
    n_layers = len(case["soil.layers"])
    for k, f in enumerate(case["uncertainty.field"]):
        out.extend(_check_field(f"uncertainty.field[{k + 1}]", f, n_layers))
    return out


def _check_correlation(corr: list, d: int, method: str) -> list[tuple[str, Any, str]]:
    key = "uncertainty.correlation"
    c = np.asarray(corr, dtype=float) if all(len(r) == len(corr) for r in corr) else None
    if c is None or c.shape != (d, d):
        return [(key, corr, f"must be {d} x {d}: one row and column per "
                 "[[uncertainty.parameter]]")]
    if not np.allclose(c, c.T) or not np.allclose(np.diag(c), 1.0) or np.abs(c).max() > 1:
        return [(key, corr, "must be symmetric with a unit diagonal and entries in [-1, 1]")]
    low = float(np.linalg.eigvalsh(c).min())
    if low <= 1e-10:
        return [(key, corr, f"not positive definite (smallest eigenvalue {low:.3g}): a "
                 "correlation matrix must be; check the signs and sizes of the entries")]
    if method == "sobol" and not np.allclose(c, np.eye(d)):
        return [(key, corr, "the sobol method needs independent parameters (Saltelli's "
                 "estimators assume them): use method = 'lhs' or 'mc', or no correlation")]
    return []


def _check_field(where: str, f: dict, n_layers: int) -> list[tuple[str, Any, str]]:
    out = []
    for name, (required, doc) in FIELD_KEYS.items():
        if required and name not in f:
            out.append((f"{where}.{name}", None, f"missing ({doc})"))
    if out:
        return out
    layer = f["layer"]
    if isinstance(layer, bool) or not isinstance(layer, int) or not 1 <= layer <= n_layers:
        out.append((f"{where}.layer", layer, f"the case gives {n_layers} soil layer(s): "
                    f"1..{n_layers}" if n_layers else "the case gives no [[soil.layers]]"))
    if f["quantity"] not in QUANTITIES:
        out.append((f"{where}.quantity", f["quantity"], "allowed: " + ", ".join(QUANTITIES)))
    if f["model"] not in MODELS:
        out.append((f"{where}.model", f["model"], "allowed: " + ", ".join(MODELS)))
    for name in ("cov", "len_h", "len_v", "nu"):
        if name in f and not (_number(f[name]) and f[name] > 0):
            out.append((f"{where}.{name}", f[name], f"must be > 0 ({FIELD_KEYS[name][1]})"))
    return out
