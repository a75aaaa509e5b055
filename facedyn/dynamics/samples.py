"""Where the removal network looks: skin samples on the face and landmarks on the skull.

Secondary dynamics are spatially smooth (papers/000 §5.1), so the network runs on about
344 skin samples and the offsets are spread to every vertex afterwards
(facedyn.dynamics.propagate). The samples are spread evenly over the soft face by
farthest-point sampling with distances along the mesh's edges, so that samples do not
jump across the open mouth or closed eyelids as straight-line distances would.

Only the outer skin gets samples (`skin_region`): a rig may carry teeth, eyeballs or a
mouth bag in the same mesh, and uv seams cut its face into charts; the stretch features
(facedyn.dynamics.stretch) look STEP_CM either side of a sample within its uv chart, so
samples keep that reach (and a margin) away from seams and open borders.

The skull landmarks b_1..b_5 only need to be rigidly attached to the skull and spread in
all three directions, so that any rotation moves some of them; when a take has none,
they are placed from the rest mesh's bounding box (see `default_landmarks`).

SciPy's graph routines are imported where samples are placed, not with the module: a face
setup read back from a model file (`usdfacedyn inspect MODEL`) only checks its samples.
"""
from __future__ import annotations

import numpy as np

from facedyn.dynamics.stretch import STEP_CM, _corner_uv_indices
from facedyn.performance import Topology, UVs

SAMPLE_COUNT = 344
RIGID_THRESHOLD = 0.99
BORDER_REACH_CM = 1.5 * STEP_CM  # samples stay this far (along the skin) from uv seams and open borders
MIN_PIECE = 0.1  # pieces of skin left between seams smaller than this share of the largest get no samples

# Default landmarks as fractions of the bounding box's half extents from its centre, in
# skull space (Y up, the face looking along +Z, the subject's left towards +X).
LANDMARK_NAMES = ("forehead", "left_temple", "right_temple", "back_of_head", "lower_face")
_LANDMARK_FRACTIONS = np.array(
    [
        [0.0, 0.55, 0.6],  # forehead centre, above the brows
        [0.8, 0.3, 0.2],  # left temple
        [-0.8, 0.3, 0.2],  # right temple
        [0.0, 0.3, -0.8],  # back of the head (just behind the face on a face-only mesh)
        [0.0, -0.35, 0.6],  # low on the centre line (the upper jaw on a face-only mesh)
    ]
)


def face_region(point_count: int, face_vertices=None, rigid_weights=None) -> np.ndarray:
    """Vertex indices to sample: the face region if given, else the non-rigid vertices.

    Non-rigid means rigid weight below RIGID_THRESHOLD; with neither given, every vertex.
    """
    if face_vertices is not None:
        region = np.unique(np.asarray(face_vertices, dtype=np.int64))
        if region.size and (region[0] < 0 or region[-1] >= point_count):
            raise ValueError(f"face vertices must lie in [0, {point_count}), got [{region[0]}, {region[-1]}]")
    elif rigid_weights is not None:
        weights = np.asarray(rigid_weights, dtype=np.float64)
        if weights.shape != (point_count,):
            raise ValueError(f"rigid weights must be ({point_count},), got {weights.shape}")
        region = np.flatnonzero(weights < RIGID_THRESHOLD)
    else:
        region = np.arange(point_count)
    if region.size == 0:
        raise ValueError("the face region is empty: no vertex to place skin samples on")
    return region


def skin_region(points, topology: Topology, uvs: UVs | None = None, region=None, reach: float = BORDER_REACH_CM) -> np.ndarray:
    """The vertices of `region` (default: all) fit for skin samples, sorted.

    Keeps the mesh's connected piece that holds most of the region's area (the face: teeth,
    eyeballs and other separate shells go), drops vertices within `reach` cm along the
    skin of a uv seam (a vertex with two uv values) or an open border, then drops the
    pieces this leaves that are smaller than MIN_PIECE of the largest (small uv islands:
    nostrils, an inner mouth chart). Teeth or a mouth bag joined to the skin without a seam
    cannot be told from skin by topology and stay in.
    """
    from scipy.sparse.csgraph import connected_components

    from facedyn.geometry import mesh
    from facedyn.geometry.mesh_topology import edge_graph, graph_distance

    pts = np.asarray(points, dtype=np.float64)
    tri = topology.triangles().astype(np.int64)
    n = len(pts)
    region = np.arange(n) if region is None else face_region(n, region)
    inside = np.zeros(n, dtype=bool)
    inside[region] = True
    area = mesh.vertex_areas(pts, tri) if len(tri) else np.zeros(n)
    graph = edge_graph(pts, tri)
    _, piece = connected_components(graph, directed=False)
    face = np.argmax(np.bincount(piece, weights=area * inside))
    keep = inside & (piece == face)
    border = np.union1d(_open_border_vertices(tri), _seam_vertices(topology, uvs))
    if border.size:
        keep &= ~(graph_distance(pts, tri, border, limit=reach) < reach)
    kept = np.flatnonzero(keep)
    if kept.size == 0:
        raise ValueError(f"no vertex of the face region lies on the outer skin at least {reach} cm from a uv seam or border")
    _, pieces = connected_components(graph[kept][:, kept], directed=False)
    size = np.bincount(pieces, weights=area[kept])
    return kept[size[pieces] >= MIN_PIECE * size.max()]


def _open_border_vertices(tri: np.ndarray) -> np.ndarray:
    """Vertices on an edge that only one triangle uses."""
    edges = np.sort(np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]]), axis=1)
    unique, count = np.unique(edges, axis=0, return_counts=True)
    return np.unique(unique[count == 1])


def _seam_vertices(topology: Topology, uvs: UVs | None) -> np.ndarray:
    """Vertices whose corners carry more than one uv value (they sit on a chart's edge)."""
    if uvs is None:
        return np.zeros(0, np.int64)
    fvi = np.asarray(topology.face_vertex_indices, dtype=np.int64)
    values = np.asarray(uvs.values, dtype=np.float64)[_corner_uv_indices(fvi, uvs)]
    pairs = np.unique(np.column_stack([fvi, values]), axis=0)
    vertex, count = np.unique(pairs[:, 0].astype(np.int64), return_counts=True)
    return vertex[count > 1]


def farthest_point_samples(points, triangles, count: int = SAMPLE_COUNT, region=None) -> np.ndarray:
    """(count,) int32 vertex indices spread evenly over ``region`` (default: all vertices).

    Deterministic: starts at the region vertex nearest the region's centroid, then adds
    the vertex farthest (along the region's edges) from every sample so far, lowest index
    on ties. A region in several pieces gets a sample in each piece first.
    """
    from scipy.sparse.csgraph import dijkstra

    from facedyn.geometry.mesh_topology import edge_graph

    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must be (N, 3), got {pts.shape}")
    region = np.arange(len(pts)) if region is None else face_region(len(pts), region)
    if int(count) != count or count < 1:
        raise ValueError(f"sample count must be a positive whole number, got {count}")
    if count > len(region):
        raise ValueError(f"cannot place {count} samples on a region of {len(region)} vertices")
    graph = edge_graph(pts, triangles)[region][:, region]
    local = pts[region]
    first = int(np.argmin(np.linalg.norm(local - local.mean(axis=0), axis=1)))
    chosen = [first]
    nearest = dijkstra(graph, directed=False, indices=first)
    for _ in range(int(count) - 1):
        nxt = int(np.argmax(nearest))
        chosen.append(nxt)
        # Only vertices closer to the new sample than the current farthest one can change.
        limit = nearest[nxt]
        nearest = np.minimum(nearest, dijkstra(graph, directed=False, indices=nxt, limit=limit))
    return region[np.asarray(chosen)].astype(np.int32)


def default_landmarks(rest_points) -> np.ndarray:
    """(5, 3) skull-space landmarks placed from the rest mesh's bounding box.

    In LANDMARK_NAMES order: forehead centre, left and right temple, back of the head,
    low on the face's centre line. They are points of the skull's rigid frame, so they
    need not lie on bone or skin, only spread out in all three directions. They are never collinear for a mesh that is not itself a line.
    """
    pts = np.asarray(rest_points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or len(pts) == 0:
        raise ValueError(f"rest points must be (N, 3), got {pts.shape}")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    landmarks = 0.5 * (lo + hi) + _LANDMARK_FRACTIONS * (0.5 * (hi - lo))
    return check_landmarks(landmarks)


def check_landmarks(landmarks) -> np.ndarray:
    """(L, 3) float64 landmarks, L >= 3, not all on one line (else rotations about that
    line would be invisible to the skull features)."""
    b = np.asarray(landmarks, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 3 or len(b) < 3:
        raise ValueError(f"skull landmarks must be (L >= 3, 3), got {b.shape}")
    spread = np.linalg.svd(b - b.mean(axis=0), compute_uv=False)
    if spread[1] <= 1e-9 * max(spread[0], 1e-300):
        raise ValueError("skull landmarks are collinear (or coincide); rotations about their line would go unseen")
    return b
