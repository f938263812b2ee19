"""The mesh check's kernels on small meshes with known defects (issue 28, item 6: the batched,
sort-based checks must still find every inverted element, duplicate or unused node,
non-conformal face, aspect ratio and per-part edge length).

Every expected number is counted by hand on a block of unit cubes."""

from __future__ import annotations

import numpy as np
import pytest

from railvib_hpc.fem.reference import element_batches
from railvib_hpc.io.formats.mesh import inverted_hexes
from railvib_hpc.mesh.model import Mesh
from railvib_hpc.mesh.search import boundary_faces, inside_any, locate, nonconformal_faces
from railvib_hpc.mesh.stage import check_quality, max_edge_per_soil_part
from railvib_hpc.schema import PART_ID


def block(nx: int, ny: int, nz: int, h=(1.0, 1.0, 1.0), origin=(0.0, 0.0, 0.0),
          part: str = "subgrade") -> Mesh:
    """A structured block of nx x ny x nz hexahedra (VTK order) of size ``h``."""
    i, j, k = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1), np.arange(nz + 1),
                          indexing="ij")
    points = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1) * np.asarray(h) \
        + np.asarray(origin)

    def node(a, b, c):
        return (a * (ny + 1) + b) * (nz + 1) + c

    e = np.stack(np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"),
                 axis=-1).reshape(-1, 3)
    a, b, c = e.T
    hexes = np.stack([node(a, b, c), node(a + 1, b, c), node(a + 1, b + 1, c),
                      node(a, b + 1, c), node(a, b, c + 1), node(a + 1, b, c + 1),
                      node(a + 1, b + 1, c + 1), node(a, b + 1, c + 1)], axis=1)
    return Mesh(points=points.astype(float), hexes=hexes.astype(np.int64),
                hex_part=np.full(len(hexes), PART_ID[part], dtype=np.int32),
                lines=np.zeros((0, 2), dtype=np.int64), line_part=np.zeros(0, dtype=np.int32))


def joined(a: Mesh, b: Mesh, merge: bool = True) -> Mesh:
    """Two meshes in one; coincident nodes merged (``merge``) or kept twice."""
    points = np.concatenate([a.points, b.points])
    hexes = np.concatenate([a.hexes, b.hexes + a.n_nodes])
    if merge:
        _, first, inverse = np.unique(np.round(points, 9), axis=0, return_index=True,
                                      return_inverse=True)
        order = np.argsort(first)                # the merged nodes in order of appearance
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        points, hexes = points[first[order]], rank[inverse.ravel()][hexes]
    return Mesh(points=points, hexes=hexes, hex_part=np.concatenate([a.hex_part, b.hex_part]),
                lines=np.zeros((0, 2), dtype=np.int64), line_part=np.zeros(0, dtype=np.int32))


def reference_boundary_faces(hexes: np.ndarray) -> np.ndarray:
    """The row-wise definition: faces whose sorted node numbers occur once."""
    from railvib_hpc.mesh.search import HEX_FACES

    faces = hexes[:, HEX_FACES].reshape(-1, 4)
    _, inverse, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True,
                                   return_counts=True)
    return faces[counts[inverse.ravel()] == 1]


def test_clean_block():
    mesh = block(3, 2, 2)
    q = check_quality(mesh, {})
    assert q["n_inverted"] == 0 and q["min_scaled_jacobian"] == pytest.approx(1.0, abs=1e-15)
    assert q["max_aspect_ratio"] == pytest.approx(1.0) and q["min_edge"] == pytest.approx(1.0)
    assert (q["duplicate_nodes"], q["unused_nodes"], q["nonconformal_faces"]) == (0, 0, 0)
    assert q["max_edge_per_soil_part"] == {"subgrade": pytest.approx(1.0)}
    # outer surface: 2 (3 x 2 + 3 x 2 + 2 x 2) = 32 faces
    assert len(boundary_faces(mesh.hexes)) == 32
    assert inverted_hexes(mesh.points, mesh.hexes) == 0


def test_one_inverted_hexahedron_is_found():
    mesh = block(3, 2, 2)
    mesh.hexes[4] = mesh.hexes[4][[4, 5, 6, 7, 0, 1, 2, 3]]        # top and bottom swapped
    q = mesh.quality()
    assert q["n_inverted"] == 1 and q["min_scaled_jacobian"] == pytest.approx(-1.0)
    assert np.flatnonzero(mesh.scaled_jacobians() <= 0).tolist() == [4]
    assert inverted_hexes(mesh.points, mesh.hexes) == 1
    flat = block(1, 1, 1)
    flat.points[flat.hexes[0, 4:], 2] = 0.0                       # squashed: zero volume
    assert flat.quality()["n_inverted"] == 1 and inverted_hexes(flat.points, flat.hexes) == 1


def test_aspect_ratio_and_edges_per_part():
    soil = block(2, 1, 1, h=(4.0, 1.0, 0.5), part="subgrade")
    ballast = block(2, 1, 1, h=(1.0, 1.0, 0.5), origin=(0.0, 0.0, 0.5), part="ballast")
    mesh = joined(soil, ballast, merge=False)
    q = mesh.quality()
    assert q["max_aspect_ratio"] == pytest.approx(8.0) and q["min_edge"] == pytest.approx(0.5)
    assert max_edge_per_soil_part(mesh) == {"ballast": pytest.approx(1.0),
                                            "subgrade": pytest.approx(4.0)}
    assert mesh.aspect_ratios().tolist() == pytest.approx([8.0, 8.0, 2.0, 2.0])
    assert mesh.edge_lengths().shape == (4, 12)


def test_duplicate_and_unused_nodes():
    a, b = block(2, 2, 1), block(2, 2, 1, origin=(0.0, 0.0, 1.0))
    merged, split = joined(a, b), joined(a, b, merge=False)
    assert merged.duplicate_nodes() == 0 and merged.n_nodes == 27
    assert split.duplicate_nodes() == 9                          # the 3 x 3 nodes at z = 1
    near = block(1, 1, 1)
    near.points = np.concatenate([near.points, near.points[:1] + 1e-10])
    assert near.duplicate_nodes() == 1 and near.unused_nodes() == 1


def test_nonconformal_faces_split_plane_and_hanging_nodes():
    a, b = block(2, 2, 1), block(2, 2, 1, origin=(0.0, 0.0, 1.0))
    split = joined(a, b, merge=False)
    # the 4 + 4 faces on the plane z = 1 are not shared, and each sees the other side
    assert nonconformal_faces(split) == 8
    assert nonconformal_faces(joined(a, b)) == 0
    plane = np.flatnonzero(np.isclose(split.points[:, 2], 1.0))
    assert nonconformal_faces(split, exclude_nodes=plane) == 0
    # one 2 x 2 x 1 hexahedron under 3 x 3 of 2/3 x 2/3 x 1: 12 hanging nodes, the big
    # face and the 9 small ones inside the model
    hanging = joined(block(1, 1, 1, h=(2.0, 2.0, 1.0)),
                     block(3, 3, 1, h=(2 / 3, 2 / 3, 1.0), origin=(0, 0, 1)))
    assert hanging.n_nodes == 8 + 32 - 4
    assert nonconformal_faces(hanging) == 10


def test_boundary_faces_equal_the_rowwise_definition():
    rng = np.random.default_rng(7)
    mesh = joined(block(3, 2, 2), block(2, 2, 1, origin=(0, 0, 2)), merge=False)
    perm = rng.permutation(mesh.n_nodes)                 # any node numbering, any hex order
    hexes = perm[mesh.hexes][rng.permutation(len(mesh.hexes))]
    hexes = np.roll(hexes, 1, axis=0)
    got, want = boundary_faces(hexes), reference_boundary_faces(hexes)
    assert got.shape == want.shape and np.array_equal(got, want)
    # node numbers beyond 32 bits take the row-wise path, with the same answer
    assert np.array_equal(boundary_faces(hexes + 2**32), want + 2**32)


def test_inside_any_agrees_with_locate():
    rng = np.random.default_rng(3)
    mesh = block(4, 3, 2)
    mesh.points += rng.uniform(-0.1, 0.1, mesh.points.shape)        # distorted, not inverted
    assert mesh.quality()["n_inverted"] == 0
    pts = rng.uniform(-0.5, 4.5, (400, 3)) * [1.0, 0.8, 0.6]
    elem, _ = locate(pts, mesh, k=8, tol=-1e-9)
    assert np.array_equal(inside_any(pts, mesh, k=8, tol=-1e-9), elem >= 0)
    assert 50 < np.count_nonzero(elem >= 0) < 350
    assert not inside_any(np.array([[100.0, 0, 0]]), mesh).any()


def test_element_batches_cover_the_range():
    assert [(s.start, s.stop) for s in element_batches(0)] == []
    spans = list(element_batches(10, 3))
    assert np.array_equal(np.concatenate([np.arange(10)[s] for s in spans]), np.arange(10))
