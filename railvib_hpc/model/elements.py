"""Element matrices of the model, grouped in batches, with their global DOF numbers.

Pure numpy: materials and sections come from the problem object
(:class:`~railvib_hpc.problem.Problem`), kernels from :mod:`railvib_hpc.fem`. Every batch
holds ``(nel, nd)`` DOF numbers (-1 for an eliminated DOF) and ``(nel, nd, nd)`` stiffness
and mass matrices.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from itertools import product

import numpy as np

from ..fem.beam import beam_mass, beam_stiffness, shear_deformation_factors, shear_modulus
from ..fem.hex8 import hex8_lumped_mass_diagonal, hex8_mass, hex8_stiffness
from ..fem.spring import spring_matrices
from ..mesh.interfaces import tributary_areas
from ..mesh.model import Mesh
from ..problem import Problem
from ..schema import INTERFACE_PARTS, PART_ID, SOLID_MATERIAL
from ..uncertainty.fields import element_factors

BEAM_MATERIAL = {"rail": ("rail", "rail"), "sleeper": ("sleeper", "sleeper")}
PAD_DIRECTION = {"pad_x": ("kx", 0), "pad_y": ("ky", 1), "pad_z": ("kz", 2)}


@dataclass
class Batch:
    """Element matrices of one group of elements.

    Element DOF ``k`` is component ``comp[k]`` of node ``conn[:, slot[k]]``.
    """

    conn: np.ndarray          # (nel, nn) nodes
    slot: np.ndarray          # (nd,) node slot of each element DOF
    comp: np.ndarray          # (nd,) component (0..5) of each element DOF
    K: np.ndarray             # (nel, nd, nd)
    M: np.ndarray | None      # (nel, nd, nd) or None (springs)

    def dofs(self, index: np.ndarray) -> np.ndarray:
        """Global DOF numbers (nel, nd), -1 where eliminated."""
        return index[self.conn[:, self.slot], self.comp]


_HEX_SLOT, _HEX_COMP = np.repeat(np.arange(8), 3), np.tile(np.arange(3), 8)
_BEAM_SLOT, _BEAM_COMP = np.repeat(np.arange(2), 6), np.tile(np.arange(6), 2)


def unique_shapes(x: np.ndarray, tol: float = 1e-9) -> tuple[np.ndarray, np.ndarray]:
    """Group elements that are translated copies of each other.

    Returns the indices of one representative per shape and, for every element, the index
    of its representative's shape. Structured meshes have few distinct shapes, so the
    element kernels run once per shape instead of once per element.
    """
    rel = x - x[:, :1, :]
    scale = max(float(np.abs(rel).max()), 1e-300)
    key = np.round(rel.reshape(len(x), -1) / (scale * tol)).astype(np.int64)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    return first, inverse.ravel()


def beam_up_vectors(x: np.ndarray) -> np.ndarray:
    """Reference vector per beam: global z, or global x for (nearly) vertical beams."""
    t = x[:, 1] - x[:, 0]
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    up = np.tile([0.0, 0.0, 1.0], (len(x), 1))
    up[np.abs(t[:, 2]) > 0.99] = [1.0, 0.0, 0.0]
    return up


def element_batches(mesh: Mesh, problem: Problem, hex_mask: np.ndarray | None = None,
                    line_mask: np.ndarray | None = None, chunk: int = 20_000,
                    with_mass: bool = True, full_hexes: np.ndarray | None = None
                    ) -> Iterator[Batch]:
    """Yield element batches of the selected elements (all if masks are None).

    Parameters
    ----------
    mesh, problem
        Model and material data.
    hex_mask, line_mask
        Boolean masks selecting the hexahedra / line elements to compute.
    chunk
        Maximum number of hexahedra per batch (bounds memory).
    with_mass
        Compute the mass matrices too (``Batch.M`` is None otherwise).
    full_hexes
        Hexahedra integrated with the plain ``"full"`` formulation whatever
        ``modal.hex_formulation`` says (the perfectly matched layers, whose memory terms
        use the plain gradients: the same formulation on both sides keeps the layer stable,
        :mod:`railvib_hpc.transient.pml`).
    """
    lumped = problem.lumped_mass
    hex_sel = np.ones(len(mesh.hexes), bool) if hex_mask is None else hex_mask
    line_sel = np.ones(len(mesh.lines), bool) if line_mask is None else line_mask

    full = np.zeros(len(mesh.hexes), bool) if full_hexes is None else full_hexes
    groups = [(problem.hex_formulation, ~full)]
    if full.any() and problem.hex_formulation != "full":
        groups.append(("full", full))
    for (part, mat_name), (formulation, which) in product(SOLID_MATERIAL.items(), groups):
        sel = np.flatnonzero(hex_sel & which & (mesh.hex_part == PART_ID[part]))
        if not len(sel):
            continue
        mat = problem.material(mat_name)
        for start in range(0, len(sel), chunk):
            conn = mesh.hexes[sel[start:start + chunk]]
            x = mesh.points[conn]
            first, shape_of = unique_shapes(x)
            xs = x[first]
            Ks = hex8_stiffness(xs, mat.E, mat.nu, formulation=formulation)
            Ms = hex8_mass(xs, mat.rho, lumped=lumped)[shape_of] if with_mass else None
            K = Ks[shape_of]
            if any(f.part == mat_name for f in problem.fields):
                # K is linear in E and M in rho: each element's matrices scaled by its
                # random-field factors at its centre
                centres = x.mean(axis=1)
                K = K * element_factors(problem.fields, mat_name, "E", centres)[:, None, None]
                if Ms is not None:
                    Ms = Ms * element_factors(problem.fields, mat_name, "rho",
                                              centres)[:, None, None]
            yield Batch(conn, _HEX_SLOT, _HEX_COMP, K, Ms)

    for part, (mat_name, sec_name) in BEAM_MATERIAL.items():
        sel = line_sel & (mesh.line_part == PART_ID[part])
        if not sel.any():
            continue
        conn = mesh.lines[sel]
        x = mesh.points[conn]
        mat, sec = problem.material(mat_name), problem.sections[sec_name]
        G = shear_modulus(mat.E, mat.nu)
        up = beam_up_vectors(x)
        ky, kz = sec.shear_coefficient_y, sec.shear_coefficient_z
        K = beam_stiffness(x, mat.E, G, sec.area, sec.iyy, sec.izz, sec.j, ky, kz, up)
        phi_y, phi_z = shear_deformation_factors(x, mat.E, G, sec.area, sec.iyy, sec.izz, ky,
                                                 kz)
        M = None
        if with_mass:
            M = beam_mass(x, mat.rho, sec.area, sec.iyy, sec.izz, up,
                          rotary_inertia=True, phi_y=phi_y, phi_z=phi_z)
            if lumped:
                M = _lump_beam(M)
        yield Batch(conn, _BEAM_SLOT, _BEAM_COMP, K, M)

    for part, (key, direction) in PAD_DIRECTION.items():
        sel = line_sel & (mesh.line_part == PART_ID[part])
        if not sel.any():
            continue
        conn = mesh.lines[sel]
        yield Batch(conn, np.array([0, 1]), np.array([direction, direction]),
                    spring_matrices(getattr(problem.pads, key), np.full(len(conn), direction)),
                    None)

    for kind, parts in INTERFACE_PARTS.items():
        sels = [line_sel & (mesh.line_part == PART_ID[part]) for part in parts]
        if not any(sel.any() for sel in sels):
            continue
        area = tributary_areas(mesh, kind, problem.interfaces[kind].width)
        for direction, sel in enumerate(sels):
            if not sel.any():
                continue
            conn = mesh.lines[sel]
            yield Batch(conn, np.array([0, 1]), np.array([direction, direction]),
                        spring_matrices(interface_stiffness(problem, kind, area[conn[:, 1]],
                                                            direction),
                                        np.full(len(conn), direction)), None)


def hex_max_frequencies(mesh: Mesh, problem: Problem) -> np.ndarray:
    """Largest natural frequency [rad/s] of every hexahedron alone, free, with its row-sum
    lumped mass: ``sqrt(lambda_max(m_e^-1/2 K_e m_e^-1/2))`` (once per distinct shape and
    material). By Irons' element eigenvalue theorem the model's largest frequency is at
    most the largest of these, so an element's own critical step bounds what it allows
    (the IMEX engine's element-wise partition, :mod:`railvib_hpc.transient.imex`)."""
    out = np.zeros(len(mesh.hexes))
    for part, mat_name in SOLID_MATERIAL.items():
        sel = np.flatnonzero(mesh.hex_part == PART_ID[part])
        if not len(sel):
            continue
        mat = problem.material(mat_name)
        x = mesh.points[mesh.hexes[sel]]
        first, shape_of = unique_shapes(x)
        xs = x[first]
        Ks = hex8_stiffness(xs, mat.E, mat.nu, formulation=problem.hex_formulation)
        d = 1.0 / np.sqrt(hex8_lumped_mass_diagonal(xs, mat.rho))
        lam = np.linalg.eigvalsh(d[:, :, None] * Ks * d[:, None, :])[:, -1]
        out[sel] = np.sqrt(np.maximum(lam, 0.0))[shape_of]
        if any(f.part == mat_name for f in problem.fields):       # omega ~ sqrt(E / rho)
            centres = x.mean(axis=1)
            out[sel] *= np.sqrt(element_factors(problem.fields, mat_name, "E", centres)
                                / element_factors(problem.fields, mat_name, "rho", centres))
    return out


def interface_stiffness(problem: Problem, kind: str, area: np.ndarray, direction: int
                        ) -> np.ndarray:
    """Stiffness of an elastic interface's springs along ``direction`` from the tributary
    ``area`` of their upper nodes (:func:`railvib_hpc.mesh.interfaces.tributary_areas`): the
    bedding modulus, times ``shear_ratio`` along x and y, times the area."""
    interface = problem.interfaces[kind]
    ratio = 1.0 if direction == 2 else interface.shear_ratio
    return interface.modulus * ratio * area


def _lump_beam(M: np.ndarray) -> np.ndarray:
    """Row-sum lumping of the translational part; rotary inertia keeps its diagonal."""
    out = np.zeros_like(M)
    diag = np.einsum("eii->ei", M).copy()
    trans = np.r_[0:3, 6:9]
    diag[:, trans] = M[:, trans][:, :, trans].sum(axis=2)
    out[:, np.arange(12), np.arange(12)] = diag
    return out


def nodal_masses(mesh: Mesh, problem: Problem, node_mask: np.ndarray) -> np.ndarray:
    """Lumped (row-sum) translational mass of every node (kg); only ``node_mask`` nodes filled.

    Hexahedra contribute their row-sum lumped mass, beams half of ``rho A L`` to each node.
    """
    out = np.zeros(mesh.n_nodes)
    hex_sel = node_mask[mesh.hexes].any(axis=1)
    for part, mat_name in SOLID_MATERIAL.items():
        sel = hex_sel & (mesh.hex_part == PART_ID[part])
        if sel.any():
            conn = mesh.hexes[sel]
            diag = hex8_lumped_mass_diagonal(mesh.points[conn],
                                             problem.material(mat_name).rho)
            out += np.bincount(conn.ravel(), weights=diag[:, 0::3].ravel(), minlength=len(out))
    for part, (mat_name, sec_name) in BEAM_MATERIAL.items():
        sel = node_mask[mesh.lines].any(axis=1) & (mesh.line_part == PART_ID[part])
        if sel.any():
            conn = mesh.lines[sel]
            length = np.linalg.norm(np.diff(mesh.points[conn], axis=1)[:, 0], axis=1)
            m = problem.material(mat_name).rho * problem.sections[sec_name].area * length
            out += np.bincount(conn.ravel(), weights=np.repeat(m / 2, 2), minlength=len(out))
    out[~node_mask] = 0.0
    return out


#: Name of the rail-pad group (its damping ratio is ``modal.damping_ratio``).
PADS = "pads"


def group_damping_ratio(problem: Problem, group: str) -> float:
    """Damping ratio of a material group: ``modal.damping_ratio`` for the rail pads, half the
    loss factor for an elastic interface, the material's otherwise."""
    if group == PADS:
        return problem.damping.ratio
    if group in INTERFACE_PARTS:
        return 0.5 * problem.interfaces[group].loss_factor
    return problem.material(group).damping_ratio


def material_groups(mesh: Mesh) -> dict[str, tuple[str, ...]]:
    """Material group -> the mesh parts it holds (groups without elements are left out)."""
    groups: dict[str, list[str]] = {}
    for part, mat in SOLID_MATERIAL.items():
        groups.setdefault(mat, []).append(part)
    for part, (mat, _) in BEAM_MATERIAL.items():
        groups.setdefault(mat, []).append(part)
    groups[PADS] = list(PAD_DIRECTION)
    for kind, parts in INTERFACE_PARTS.items():
        groups[kind] = list(parts)
    present = set(np.unique(mesh.hex_part).tolist()) | set(np.unique(mesh.line_part).tolist())
    return {g: tuple(parts) for g, parts in groups.items()
            if any(PART_ID[p] in present for p in parts)}
