"""Element stresses of the solids and bending moments of the rails from reconstructed fields.

Solids
------
:func:`element_stress` evaluates, at the centre of every 8-node hexahedron, the small
strain ``eps = sym(grad u)`` of the trilinear displacement field and the isotropic
linear-elastic stress ``sigma = lambda tr(eps) I + 2 mu eps`` with the element's
part material. It returns

* the von Mises stress ``sigma_vm = sqrt(3/2 s:s)`` (``s`` deviatoric stress), and
* the von Mises equivalent strain in the ANSYS convention (``EPEL EQV`` with the
  material's Poisson ratio)::

      eps_eq = 1 / (1 + nu) * sqrt(1/2 [(exx - eyy)^2 + (eyy - ezz)^2 + (ezz - exx)^2]
                                   + 3 (exy^2 + eyz^2 + ezx^2))

  (tensor shear strains), so that ``sigma_vm = E eps_eq`` for every elastic strain state
  (e.g. ``eps_eq = eps`` for uniaxial stress).

The centre value equals the element average for parallelepipeds (and is what the
B-bar hexahedron of :mod:`railvib_hpc.fem.hex8` gives there). All kernels are batched
over elements (and times), without Python loops over elements.

:func:`stress_from_fields` is the parallel driver: for the stored steps nearest to the
requested times every rank reads its node slice of ``/fields/displacement``, the full
field is assembled with ``Allgatherv`` and every rank evaluates an even share of the
hexahedra. It writes ``/stress/von_mises`` (n_sel, n_hex) [Pa], ``/stress/strain_eq``
(n_sel, n_hex) [-], ``/stress/time`` (n_sel,) and ``/stress/steps`` (n_sel,) into
``fields.h5`` (attribute ``stress_complete`` = 1 once written) and ``stress.xdmf``
(cell data, one grid per selected time).

Rails
-----
:func:`rail_bending_moment` gives the vertical bending moment ``M = E I kappa`` of a
straight Timoshenko rail from its nodal vertical displacements ``w`` (global z) and
rotations ``ry`` (about global y), with the interdependent shape functions of
:mod:`railvib_hpc.fem.beam` (exact for end-loaded elements; ``kappa`` is linear in each
element).

Sign convention: the rail runs along +x, z is up, the section rotation is
``psi = -ry`` (= ``dw/dx`` without shear deformation, as in
:mod:`railvib_hpc.mbs.coupling`) and ``M = E I dpsi/dx``. **Positive M is sagging**
(bottom fibre in tension, concave upwards), as under a wheel; hogging between the
wheels of a bogie is negative.
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..fem.beam import shear_deformation_factors, shear_modulus
from ..fem.material import lame_parameters
from ..fem.reference import hex_centre_gradients
from ..io.files import STRESS_XDMF
from ..io.formats.fields import FieldsFile
from ..io.parallel_h5 import h5py_parallel_ok, open_h5, read_slab, write_slab
from ..io.temp_names import final_name
from ..log import Reporter
from ..parallel import check_collective, on_root
from ..problem import Problem
from ..schema import PART_ID
from .fields import node_range

if TYPE_CHECKING:
    from mpi4py import MPI

#: Elements per block in :func:`element_stress` (bounds temporary memory).
_BLOCK = 65536


def hex_materials(problem: Problem) -> dict[int, tuple[float, float]]:
    """Part id -> ``(E, nu)`` of every solid part, from the problem's materials.

    Parameters
    ----------
    problem
        The problem (``materials.<material>.E`` / ``.nu``, the soil layers').

    Returns
    -------
    dict
        Keys are :data:`railvib_hpc.schema.PART_ID` values of the solid parts.
    """
    from ..model.elements import SOLID_MATERIAL

    out = {}
    for part, mat in SOLID_MATERIAL.items():
        props = problem.materials.get(mat)
        if props is None:             # a soil layer the case does not have
            continue
        out[PART_ID[part]] = (float(props.E), float(props.nu))
    return out


def _material_arrays(hex_part: np.ndarray, materials: Mapping[int, tuple[float, float]]
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Per-element ``(E, nu)`` from the part ids."""
    parts = np.unique(hex_part)
    missing = [int(p) for p in parts if int(p) not in materials]
    if missing:
        raise ValueError(f"no material (E, nu) for hex part id(s) {missing}")
    lut_e = np.zeros(int(parts.max()) + 1 if len(parts) else 1)
    lut_nu = np.zeros_like(lut_e)
    for p in parts:
        lut_e[p], lut_nu[p] = materials[int(p)]
    return lut_e[hex_part], lut_nu[hex_part]


def strain_measures(eps: np.ndarray, E: np.ndarray, nu: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Von Mises stress and equivalent strain from small-strain tensors.

    Parameters
    ----------
    eps
        Strain tensors (..., nel, 3, 3) (symmetric, tensor shear components).
    E, nu
        (nel,) Young's moduli and Poisson's ratios.

    Returns
    -------
    von_mises, strain_eq : ndarray, shape (..., nel)
    """
    _, mu = lame_parameters(E, nu)
    dev = eps - np.trace(eps, axis1=-2, axis2=-1)[..., None, None] * np.eye(3) / 3.0
    j2 = 0.5 * np.einsum("...ij,...ij->...", dev, dev)           # J2 of the strain
    root = np.sqrt(3.0 * np.maximum(j2, 0.0))                   # sqrt(1/2 [...]) of ANSYS
    return 2.0 * mu * root, root / (1.0 + nu)


def element_stress(points: np.ndarray, hexes: np.ndarray, hex_part: np.ndarray,
                   materials: Mapping[int, tuple[float, float]], u: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Von Mises stress and equivalent strain at the centre of every hexahedron.

    Parameters
    ----------
    points
        (n, 3) node coordinates.
    hexes
        (nel, 8) hexahedra, VTK order.
    hex_part
        (nel,) part ids.
    materials
        Part id -> ``(E, nu)`` (see :func:`hex_materials`).
    u
        Nodal displacements (n, 3) or, for several times, (nt, n, 3).

    Returns
    -------
    von_mises : ndarray, shape (nel,) or (nt, nel)
        Von Mises stress [Pa].
    strain_eq : ndarray, same shape
        Von Mises equivalent strain [-] (``= von_mises / E``).
    """
    points = np.asarray(points, dtype=float)
    hexes = np.asarray(hexes)
    u = np.asarray(u, dtype=float)
    single = u.ndim == 2
    if single:
        u = u[None]
    if u.ndim != 3 or u.shape[1:] != points.shape:
        raise ValueError(f"u must be (n, 3) or (nt, n, 3) with n = {len(points)}, got {u.shape}")
    E, nu = _material_arrays(np.asarray(hex_part), materials)
    nel = len(hexes)
    vm = np.empty((u.shape[0], nel))
    eq = np.empty((u.shape[0], nel))
    for s in range(0, nel, _BLOCK):
        e = slice(s, min(s + _BLOCK, nel))
        conn = hexes[e]
        g = hex_centre_gradients(points[conn])                    # (b, 8, 3)
        grad = np.einsum("teai,eaj->teij", u[:, conn], g)          # du_i / dx_j
        eps = 0.5 * (grad + grad.swapaxes(-1, -2))
        vm[:, e], eq[:, e] = strain_measures(eps, E[e], nu[e])
    if single:
        return vm[0], eq[0]
    return vm, eq


# --------------------------------------------------------------------------- rails
def rail_bending_moment(x: np.ndarray, w: np.ndarray, ry: np.ndarray, EI: float,
                        phi: float | np.ndarray = 0.0, per_element: bool = False
                        ) -> np.ndarray:
    """Vertical bending moment ``M = E I dpsi/dx`` of a straight rail (sagging positive).

    Parameters
    ----------
    x
        (k,) node positions along the rail, strictly increasing.
    w
        (..., k) vertical displacements (global z, up positive) [m].
    ry
        (..., k) rotations about global y [rad]; the section rotation is ``psi = -ry``.
    EI
        Bending stiffness in the vertical plane [N m^2].
    phi
        Timoshenko shear-deformation factor ``12 E I / (k G A L^2)`` per element
        ((k-1,) or scalar); 0 gives the Euler-Bernoulli (Hermite) element.
    per_element
        Return the moments at both ends of every element instead of nodal values.

    Returns
    -------
    ndarray
        ``per_element=False``: (..., k) nodal moments [N m]: the end values of the two
        adjacent elements averaged at interior nodes. They differ by the concentrated
        moment applied at the node, which is not small where the rail rotations are fixed
        (``modal.fix_rail_rotations_at_pads``, thesis App. A: the reaction moment of the
        fixed rotation): there the element end values are the meaningful ones.
        ``per_element=True``: (..., k-1, 2) moments at the start and end of each element.
    """
    x = np.asarray(x, dtype=float)
    w = np.asarray(w, dtype=float)
    psi = -np.asarray(ry, dtype=float)
    if np.any(np.diff(x) <= 0):
        raise ValueError("rail node positions must be strictly increasing")
    L = np.diff(x)
    f = np.broadcast_to(np.asarray(phi, dtype=float), L.shape)
    c = 1.0 / (1.0 + f)
    # dpsi/dx = (1/L) dNpsi/ds . (w0, psi0, w1, psi1), dNpsi/ds of fem.beam's Npsi
    w0, w1, p0, p1 = w[..., :-1], w[..., 1:], psi[..., :-1], psi[..., 1:]
    ends = []
    for s in (0.0, 1.0):
        d = (c * 6 * (2 * s - 1) / L * (w0 - w1) + c * (6 * s - (4 + f)) * p0
             + c * (6 * s - (2 - f)) * p1) / L
        ends.append(EI * d)
    m_el = np.stack(ends, axis=-1)                                 # (..., k-1, 2)
    return m_el if per_element else _nodal(m_el)


def _nodal(m_el: np.ndarray) -> np.ndarray:
    """Nodal values (..., k) from element end values (..., k-1, 2): interior nodes averaged."""
    out = np.empty(m_el.shape[:-2] + (m_el.shape[-2] + 1,))
    out[..., 0] = m_el[..., 0, 0]
    out[..., -1] = m_el[..., -1, 1]
    out[..., 1:-1] = 0.5 * (m_el[..., :-1, 1] + m_el[..., 1:, 0])
    return out


def rail_section(problem: Problem) -> dict[str, float]:
    """Vertical-plane bending data of the flexible rail from the problem.

    Returns
    -------
    dict
        ``EI`` [N m^2], ``E``, ``G``, ``A``, ``I``, ``k`` (shear coefficient).
    """
    E, nu = problem.material("rail").E, problem.material("rail").nu
    sec = problem.sections["rail"]
    return {"E": float(E), "G": float(shear_modulus(E, nu)), "A": float(sec.area),
            "I": float(sec.iyy), "k": float(sec.shear_coefficient_y),
            "EI": float(E * sec.iyy)}


def rail_moment_modes(modes_path: str | os.PathLike, m: int, problem: Problem | None = None
                      ) -> dict[str, np.ndarray]:
    """Bending moment of each mode shape at the flexible-rail nodes (rank 0, serial).

    The moment is linear in the modal coordinates, so ``M(t) = q(t) @ moment`` (see
    :func:`rail_moment_history`).

    Parameters
    ----------
    modes_path
        A complete ``modes.h5`` (``/mesh/rail_nodes``, ``/modes/rotation``).
    m
        Number of modes used.
    problem
        Materials and sections (default: those of the case stored in ``modes.h5``,
        :meth:`~railvib_hpc.problem.Problem.from_modes`).

    Returns
    -------
    dict
        ``x`` (r, k) node positions, ``y`` (r,) rail positions, ``nodes`` (r, k) node ids,
        ``moment`` (m, r, k) nodal moments and ``moment_ends`` (m, r, k-1, 2) moments at
        both ends of every rail element [N m per unit modal coordinate], ``EI``; r = 2 rails
        per track, by increasing y.
    """
    import h5py

    with h5py.File(modes_path, "r") as f:
        if problem is None:
            problem = Problem.from_modes(f)
        rails = f["mesh/rail_nodes"][()]
        if rails.size == 0 or np.any(rails < 0):
            raise ValueError(f"{modes_path}: no rail nodes (or rails of different lengths)")
        pts = f["mesh/points"][()]
        rot_nodes = f["mesh/rotation_nodes"][()]
        sec = rail_section(problem)
        xs, moments, ends = [], [], []
        for nodes in rails:
            order = np.argsort(nodes)
            w = np.empty((m, len(nodes)))
            w[:, order] = f["modes/translation"][:m, nodes[order], 2]
            pos = np.searchsorted(rot_nodes, nodes)
            if not np.array_equal(rot_nodes[np.minimum(pos, len(rot_nodes) - 1)], nodes):
                raise ValueError(f"{modes_path}: rail nodes without rotations")
            r = np.empty((m, len(nodes)))
            r[:, order] = f["modes/rotation"][:m, pos[order], 1]
            x = pts[nodes, 0]
            seg = np.stack([pts[nodes[:-1]], pts[nodes[1:]]], axis=1)
            phi_y, _ = shear_deformation_factors(seg, sec["E"], sec["G"], sec["A"], sec["I"],
                                                 sec["I"], sec["k"], sec["k"])
            m_el = rail_bending_moment(x, w, r, sec["EI"], phi_y, per_element=True)
            ends.append(m_el)
            moments.append(_nodal(m_el))
            xs.append(x)
    return {"x": np.array(xs), "y": pts[rails[:, 0], 1], "nodes": rails,
            "moment": np.stack(moments, axis=1), "moment_ends": np.stack(ends, axis=1),
            "EI": np.float64(sec["EI"])}


def rail_moment_history(q: np.ndarray, moment: np.ndarray) -> np.ndarray:
    """Bending-moment histories ``(nt, ...)`` from modal coordinates ``q`` (nt, m).

    ``moment`` is ``moment`` (m, 2, k) or ``moment_ends`` (m, 2, k-1, 2) of
    :func:`rail_moment_modes`.
    """
    m = moment.shape[0]
    return (np.asarray(q)[:, :m] @ moment.reshape(m, -1)).reshape((len(q),) + moment.shape[1:])


# --------------------------------------------------------------------------- parallel driver
def select_steps(times: np.ndarray, wanted: Sequence[float]) -> np.ndarray:
    """Indices of the stored times nearest to ``wanted`` (ValueError outside the range)."""
    times = np.asarray(times, dtype=float)
    wanted = np.atleast_1d(np.asarray(wanted, dtype=float))
    tol = 1e-9 * max(1.0, float(np.abs(times).max()))
    bad = wanted[(wanted < times[0] - tol) | (wanted > times[-1] + tol)]
    if bad.size:
        raise ValueError(f"stress times {bad.tolist()} are outside the stored time range "
                         f"[{times[0]}, {times[-1]}] s")
    pos = np.clip(np.searchsorted(times, wanted), 1, len(times) - 1) if len(times) > 1 \
        else np.zeros(len(wanted), dtype=np.int64)
    if len(times) > 1:
        left = times[pos - 1]
        pos = np.where(np.abs(wanted - left) <= np.abs(times[pos] - wanted), pos - 1, pos)
    return pos.astype(np.int64)


def stress_from_fields(fields_path: str | os.PathLike, comm: MPI.Comm, times: Sequence[float],
                       materials: Mapping[int, tuple[float, float]], *,
                       rep: Reporter | None = None, attrs: Mapping[str, object] | None = None,
                       require_complete: bool = True) -> dict:
    """Element stresses at selected times from ``fields.h5``; adds ``/stress`` (collective).

    Parameters
    ----------
    fields_path
        A complete ``fields.h5`` (:func:`~railvib_hpc.reconstruct.fields.reconstruct_fields`).
    comm
        MPI communicator.
    times
        Requested times [s]; the nearest stored steps are used (their times are written to
        ``/stress/time``).
    materials
        Part id -> ``(E, nu)``.
    rep
        Progress reporter.
    attrs
        Attributes of the ``/stress`` group (e.g. an input digest).
    require_complete
        Refuse a ``fields.h5`` whose ``complete`` attribute is not 1. ``False`` is for the
        temporary file inside :func:`reconstruct_fields` (``before_complete``), which makes
        fields and stresses one atomic result.

    Returns
    -------
    dict
        ``n_times``, ``n_hexes``, ``seconds``, ``max_von_mises`` (Pa), ``times``.

    Raises
    ------
    ValueError
        Times outside the stored range or missing materials (on every rank).
    """
    t_start = time.perf_counter()
    fields_path = Path(fields_path)
    parallel = h5py_parallel_ok(comm)

    complete, stored, ushape, hshape = on_root(FieldsFile(fields_path).header, comm)
    if require_complete and complete != 1:  # the same decision on every rank
        raise ValueError(f"{fields_path} is not complete")
    sel = select_steps(stored, times)
    t_sel = stored[sel]
    n, ne, n_sel = ushape[1], hshape[0], len(sel)
    nodes = node_range(n, comm.size, comm.rank)
    elems = node_range(ne, comm.size, comm.rank)
    nl = nodes.stop - nodes.start
    counts = np.array(comm.allgather(3 * nl), dtype=np.int64)
    displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
    vm = np.empty((n_sel, elems.stop - elems.start))
    eq = np.empty_like(vm)
    error = None
    try:
        with open_h5(fields_path, "r", comm, parallel) as f:
            ds = f["fields/displacement"]
            own = np.empty((n_sel, nl, 3), dtype=ds.dtype)
            for i, k in enumerate(sel):
                read_slab(ds, (int(k), nodes.start, 0), (1, nl, 3), own[i:i + 1] if nl else None,
                          parallel)
            points = f["mesh/points"][()]
            hexes = f["mesh/hexes"][elems]
            part = f["mesh/hex_part"][elems]
    except Exception as exc:      # re-raised on every rank
        error = exc
    check_collective(comm, error, f"reading {fields_path}")
    t_first = time.perf_counter()
    full = np.empty((n, 3))
    for i in range(n_sel):
        mine = np.ascontiguousarray(own[i], dtype=float).reshape(-1)
        if comm.size > 1:
            from mpi4py import MPI

            comm.Allgatherv(mine, [full.reshape(-1), counts, displs, MPI.DOUBLE])
        else:
            full[...] = own[i]
        error = None
        try:
            vm[i], eq[i] = element_stress(points, hexes, part, materials, full)
        except Exception as exc:  # re-raised on every rank
            error = exc
        check_collective(comm, error, "computing element stresses")
        if rep is not None:
            rep.progress(f"stress: {i + 1}/{n_sel} times", i + 1, n_sel, t_first)
    _write_stress(fields_path, comm, parallel, vm, eq, sel, t_sel, elems, ne, attrs)
    vmax = comm.allreduce(float(vm.max()) if vm.size else 0.0, op=_max_op())

    def xdmf():
        # the XDMF refers to the final name, also when called on a temporary file
        write_stress_xdmf(fields_path, final_name(fields_path.name))

    on_root(xdmf, comm)
    return {"n_times": n_sel, "n_hexes": ne, "seconds": time.perf_counter() - t_start,
            "max_von_mises": vmax, "times": [float(x) for x in t_sel]}


def _max_op():
    from mpi4py import MPI

    return MPI.MAX


def _write_stress(path: Path, comm: MPI.Comm, parallel: bool, vm: np.ndarray, eq: np.ndarray,
                  sel: np.ndarray, t_sel: np.ndarray, elems: slice, ne: int,
                  attrs: Mapping[str, object] | None = None) -> None:
    """Write ``/stress`` into ``fields.h5`` (parallel, or gathered to rank 0)."""
    n_sel = len(sel)
    if not parallel and comm.size > 1:
        parts = comm.gather((vm, eq), root=0)
        if comm.rank == 0:
            vm = np.concatenate([p[0] for p in parts], axis=1)
            eq = np.concatenate([p[1] for p in parts], axis=1)
            elems = slice(0, ne)
    writes = parallel or comm.rank == 0
    error = None
    if writes:
        try:
            with open_h5(path, "a", comm if parallel else None, parallel) as f:
                if "stress" in f:
                    del f["stress"]
                f.attrs["stress_complete"] = 0
                g = f.create_group("stress")
                d_vm = g.create_dataset("von_mises", (n_sel, ne), "f8")
                d_eq = g.create_dataset("strain_eq", (n_sel, ne), "f8")
                d_t = g.create_dataset("time", (n_sel,), "f8")
                d_s = g.create_dataset("steps", (n_sel,), "i8")
                g.attrs["units"] = "von_mises: Pa, strain_eq: -, time: s"
                for key, value in (attrs or {}).items():
                    g.attrs[key] = value
                if comm.rank == 0:
                    d_t[...] = t_sel
                    d_s[...] = sel
                ne_l = elems.stop - elems.start
                for d, a in ((d_vm, vm), (d_eq, eq)):
                    write_slab(d, (0, elems.start), (n_sel, ne_l), a if ne_l else None, parallel)
                f.attrs["stress_complete"] = 1
        except Exception as exc:  # re-raised on every rank
            error = exc
    check_collective(comm, error, f"writing /stress into {path}")


def write_stress_xdmf(h5_path: str | os.PathLike, name: str | None = None) -> Path:
    """Write ``stress.xdmf`` (+ ``stress_views.h5``) next to ``h5_path``: ``/stress`` as
    cell data, one grid per selected time (serial).

    Parameters
    ----------
    h5_path
        A ``fields.h5`` with ``/stress`` (or the temporary file that becomes it).
    name
        File name the XDMF refers to (default: ``h5_path``'s name).

    Returns
    -------
    Path
        The XDMF file.
    """
    from ..io.formats.fields import write_series_xdmf

    h5_path = Path(h5_path)
    return write_series_xdmf(h5_path, name or h5_path.name, "stress/time", "stress",
                             ("von_mises", "strain_eq"), "Cell", h5_path.with_name(STRESS_XDMF))
