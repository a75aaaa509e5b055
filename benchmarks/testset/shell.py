"""The test actors' tissue geometry: a tetrahedral layer under the skin, and where it meets bone.

MuJoCo simulates volumes, a face rig is a surface. The layer is the skin extruded inward
along smoothed normals (`layers` prisms deep, each split into three tetrahedra). The bone
is this model's own: the skin pushed in by the tissue depth, thin where the skin lies on a
heavily smoothed version of itself (forehead, temples, chin) and deep where it bulges out
of it (cheeks, lips, nose), times a smooth random field per actor. The layer is at most
`max_depth` deep; its inner nodes are pinned to the bone where it reaches the bone (within
`pin_gap`), elsewhere they hang over deeper tissue and cavities (mouth, cheeks) and are held
only by soft "muscle" springs (`testset.tissue.TissueParams.muscle_hz`). Nothing here reads facedyn's rigid
weights or its simulators' layouts: only the rig's neutral, triangles and face region.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from facedyn.geometry import mesh

_SMOOTH_ITERATIONS = 300  # umbrella smoothing of the skin: it shrinks toward a membrane under the face
_FLAT_PERCENTILE = 40  # this share of the face, where it bulges least from the membrane, has the thinnest tissue
_NORMAL_SMOOTHING = 10  # smoothing of the extrusion direction, so that neighbouring columns do not cross
_MIN_QUALITY = 0.2  # a tetrahedron below this fraction of its prism's ideal volume counts as folded
_SHRINK_ROUNDS = 15
_DROP_ROUNDS = 12  # rounds of dropping the triangles that still fold (the ICT rig needs 8: about 600 of 18,461)


@dataclass(frozen=True)
class Shell:
    """A tetrahedral tissue layer; lengths in metres (MuJoCo's units)."""

    nodes: np.ndarray  # (V, 3) rest positions, skull space, m
    tets: np.ndarray  # (T, 4) int, positive orientation
    skin: np.ndarray  # (S,) rig vertex of node s (nodes[:S] are the skin)
    inner: np.ndarray  # (S,) node index of the inner end of skin node s's column
    pinned: np.ndarray  # (S,) bool: the column's inner node is on the bone
    rim: np.ndarray  # (S,) bool: skin node on the face region's edge, where the tissue goes on into the scalp and neck
    depth: np.ndarray  # (S,) layer depth, m
    bone_depth: np.ndarray  # (S,) skin-to-bone depth, m

    @property
    def masses(self) -> np.ndarray:
        """Lumped node masses (kg) at 1 kg / m^3; scale by the density."""
        volume = tet_volumes(self.nodes, self.tets)
        return np.bincount(self.tets.ravel(), np.repeat(volume / 4, 4), minlength=len(self.nodes))


def tet_volumes(nodes: np.ndarray, tets: np.ndarray) -> np.ndarray:
    a, b, c, d = (nodes[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def face_triangles(triangles: np.ndarray, face_vertices: np.ndarray) -> np.ndarray:
    """The triangles of the face region (every corner in it): the skin that has tissue."""
    inside = np.zeros(int(triangles.max()) + 1, bool)
    inside[face_vertices[face_vertices <= triangles.max()]] = True
    return triangles[inside[triangles].all(axis=1)]


def build_shell(neutral_cm: np.ndarray, triangles: np.ndarray, face_vertices: np.ndarray, *, max_depth_cm: float,
                min_bone_depth_cm: float, bulge_gain: float, layers: int, pin_gap_cm: float, depth_field: np.ndarray | None = None) -> Shell:
    """The tissue layer under the face region of a rig's neutral (cm, Y up, face toward +Z).

    `depth_field`: a per-rig-vertex factor on the bone depth (the actor's variation), 1 if None.
    Triangles whose prisms still fold after the depth is shrunk (creases such as eyelid rims
    and mouth corners, where the smoothed normal lies nearly in the triangle) get no tissue:
    their skin follows the rig and the skull like the rest of the head.
    """
    tri = face_triangles(np.asarray(triangles), np.asarray(face_vertices))
    for _ in range(_DROP_ROUNDS):
        shell, folded = _shell_under(np.asarray(neutral_cm, np.float64), tri, max_depth_cm, min_bone_depth_cm, bulge_gain, layers,
                                     pin_gap_cm, depth_field)
        if shell is not None:
            return shell
        tri = tri[~folded]
    raise ValueError(f"the tissue layer still folds after dropping the folded triangles {_DROP_ROUNDS} times")


def _shell_under(neutral_cm, tri, max_depth_cm, min_bone_depth_cm, bulge_gain, layers, pin_gap_cm, depth_field):
    """(the shell under the rig triangles `tri`, None) or (None, which triangles still fold)."""
    skin = np.unique(tri)
    local = np.full(len(neutral_cm), -1)
    local[skin] = np.arange(len(skin))
    tri = local[tri]
    points = neutral_cm[skin] / 100.0
    normals = mesh.vertex_normals(points, tri)
    flip = np.mean(np.einsum("ij,ij->i", normals, points - points.mean(axis=0))) < 0
    if flip:
        normals, tri = -normals, tri[:, ::-1]  # outward: away from the head's inside
    walk = _umbrella(tri, len(points))
    smooth_normals = normals
    for _ in range(_NORMAL_SMOOTHING):
        smooth_normals = mesh.normalize(walk @ smooth_normals)
    smoothed = points.copy()
    for _ in range(_SMOOTH_ITERATIONS):
        smoothed = 0.5 * smoothed + 0.5 * (walk @ smoothed)
    bulge = np.einsum("ij,ij->i", points - smoothed, smooth_normals)
    bulge = np.maximum(bulge - np.percentile(bulge, _FLAT_PERCENTILE), 0.0)  # the flattest part of the face lies on bone
    factor = np.ones(len(points)) if depth_field is None else np.asarray(depth_field, np.float64)[skin]
    bone_depth = (min_bone_depth_cm / 100.0 + bulge_gain * bulge) * factor
    depth = np.minimum(bone_depth, max_depth_cm / 100.0)
    for _ in range(_SHRINK_ROUNDS):  # shrink columns where the layer would fold (tight concave curvature)
        nodes, tets, ideal = _extrude(points, smooth_normals, tri, depth, layers)
        folded = tet_volumes(nodes, tets) < _MIN_QUALITY * ideal
        if not folded.any():
            break
        bad = np.unique(tets[folded] % len(points))
        depth[bad] *= 0.8
    else:
        folded_triangles = np.zeros(len(tri), bool)
        folded_triangles[(np.flatnonzero(folded) % (3 * len(tri))) // 3] = True
        return None, folded_triangles
    pinned = bone_depth - depth <= pin_gap_cm / 100.0
    return Shell(nodes=nodes, tets=tets, skin=skin, inner=np.arange(len(points)) + layers * len(points), pinned=pinned, rim=_rim(tri, len(points)),
                 depth=depth, bone_depth=bone_depth), None


def _rim(tri: np.ndarray, n: int) -> np.ndarray:
    """Vertices on a boundary edge (an edge of one triangle only)."""
    e = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    keys, counts = np.unique(e[:, 0] * n + e[:, 1], return_counts=True)
    rim = np.zeros(n, bool)
    rim[np.concatenate([keys[counts == 1] // n, keys[counts == 1] % n])] = True
    return rim


def _umbrella(tri: np.ndarray, n: int) -> sp.csr_matrix:
    """Row-normalized vertex adjacency: one step of umbrella averaging."""
    edges = mesh.unique_edges(tri)
    adjacency = sp.coo_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]], np.r_[edges[:, 1], edges[:, 0]])), shape=(n, n)).tocsr()
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    return sp.diags(1.0 / np.maximum(degree, 1)) @ adjacency


def _extrude(points, normals, tri, depth, layers):
    """Columns of `layers` + 1 nodes (level k: points - normals * depth * k / layers), each
    prism split into three tetrahedra by the vertex-index rule (conforming across prisms);
    (nodes, tets, each tet's ideal volume: a third of its prism's)."""
    n = len(points)
    levels = [points - normals * (depth * k / layers)[:, None] for k in range(layers + 1)]
    nodes = np.concatenate(levels)
    order = np.argsort(tri, axis=1)
    sorted_tri = np.take_along_axis(tri, order, axis=1)
    tets, ideal = [], []
    area = np.linalg.norm(np.cross(points[tri[:, 1]] - points[tri[:, 0]], points[tri[:, 2]] - points[tri[:, 0]]), axis=1) / 2
    for k in range(layers):
        a, b, c = (sorted_tri[:, j] + k * n for j in range(3))
        a2, b2, c2 = a + n, b + n, c + n
        # sorted corners: a shared quad face gets the same diagonal from both prisms (a conforming mesh)
        block = np.stack([np.stack([a, b, c, a2], 1), np.stack([b, c, a2, b2], 1), np.stack([c, a2, b2, c2], 1)], 1)
        tets.append(block.reshape(-1, 4))
        thickness = depth[tri].mean(axis=1) / layers
        ideal.append(np.repeat(area * thickness / 3, 3))
    tets = np.concatenate(tets)
    volume = tet_volumes(nodes, tets)
    tets = np.where((volume < 0)[:, None], tets[:, [0, 2, 1, 3]], tets)  # the sorted order loses the winding: fix it per tet
    return nodes, tets, np.concatenate(ideal)
