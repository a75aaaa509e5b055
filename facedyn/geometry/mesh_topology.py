"""Distances along a mesh's edges.

Rig masks (how rigidly skin follows the skull, how far a vertex is from a landmark) should
follow the surface, not cut through the head: the lips are close to the nose in space but
not along the skin when the mouth is open. Edge-graph (Dijkstra) distance over the
triangulated mesh is a cheap, robust approximation of geodesic distance for that.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from facedyn.geometry.mesh import unique_edges


def edge_graph(points: np.ndarray, triangles: np.ndarray) -> sp.csr_matrix:
    """(N, N) symmetric sparse matrix of edge lengths between vertices joined by a triangle edge."""
    pts = np.asarray(points, dtype=np.float64)
    edges = unique_edges(triangles)
    lengths = np.linalg.norm(pts[edges[:, 0]] - pts[edges[:, 1]], axis=1)
    # csgraph reads an explicit 0 as "no edge"; coincident vertices stay joined at a tiny length.
    lengths = np.maximum(lengths, 1e-12)
    n = len(pts)
    rows = np.concatenate([edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 1], edges[:, 0]])
    return sp.csr_matrix((np.concatenate([lengths, lengths]), (rows, cols)), shape=(n, n))


def graph_distance(points: np.ndarray, triangles: np.ndarray, sources: np.ndarray, limit: float = np.inf) -> np.ndarray:
    """(N,) distance from each vertex to the nearest source vertex along mesh edges.

    Vertices farther than `limit` (or unreachable) get +inf; a finite limit makes the
    search stop early, which is all a falloff of known width needs.
    """
    sources = np.asarray(sources, dtype=np.int64)
    n = len(points)
    if sources.size == 0:
        return np.full(n, np.inf)
    if sources.min() < 0 or sources.max() >= n:
        raise ValueError(f"source vertices must lie in [0, {n}), got [{sources.min()}, {sources.max()}]")
    return dijkstra(edge_graph(points, triangles), directed=False, indices=sources, min_only=True, limit=limit)
