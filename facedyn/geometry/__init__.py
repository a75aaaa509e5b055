"""Geometry on arrays: rigid transforms, (dual) quaternions, B-splines, mesh operators."""
from facedyn.lazy_exports import lazy_exports

_PUBLIC = {
    "VertexNormals": "mesh", "cotangent_laplacian": "mesh", "face_normals": "mesh", "mass_matrix": "mesh",
    "unique_edges": "mesh",
    "edge_graph": "mesh_topology", "graph_distance": "mesh_topology",
}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
