"""Surface stretch of the skin samples in uv space: the synthesis network's expression feature.

Paper 000, eq. 8: ``s_i(t) = ((|D_u y_i(t)| - |D_u y_i(0)|) / |D_u y_i(0)|, same for v)`` with
``D_u y_i = y(p_u+) - y(p_u-)`` a central difference over about 2 mm either side of sample i
along the surface's u direction (likewise v). The points p+- do not depend on the frame, so
`UVNeighbourhoods.build` finds them once on the neutral, as barycentric points in mesh
triangles; every frame then costs a 12-point weighted sum per sample, in NumPy or in one
OpenCL launch for all frames and samples (`stretch_features`).

Charts: a uv chart is a connected uv island, triangles joined through corners that share
both the vertex and its uv value. A vertex on a seam has one uv per side; a sample takes the
side with the most neutral surface area around it and searches only that chart's triangles,
so a search never crosses a seam, another island or another uv tile. Where p+ (or p-) falls
off the chart, that end is replaced by the sample itself: the difference becomes one-sided
(half as long, which the relative stretch does not see) and `one_sided` records it.

The uv step h starts from the neutral's uv-to-surface Jacobian at the sample and is then
refined per end until the point lies `step` cm from the sample on the neutral, because uv
density changes within millimetres around the lips and eyelids (see `_march`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from facedyn.kernels import runtime
from facedyn.performance import Topology, UVs

# Half-width of the differences on the neutral surface (cm): the paper's "roughly 2 mm".
STEP_CM = 0.2

# Rescalings of a uv step towards `step` cm, and how far from it (relative) an end may stay.
_MARCH_ITERATIONS = 16
_TOLERANCE = 0.25

# Barycentric slack that still counts as inside: ±h points land exactly on edges of regular grids.
_INSIDE = 1e-6


@dataclass(frozen=True, eq=False)
class UVNeighbourhoods:
    """Where the ±h points of every sample lie on the mesh; depends only on the neutral and uvs.

    Axis 1 of `vertices`/`weights` is the direction (u, v), axis 2 the end (minus, plus),
    axis 3 the triangle corner: point = sum_k weights[..., k] * y[vertices[..., k]].
    """

    samples: np.ndarray  # (S,) int32 sample vertex indices
    vertices: np.ndarray  # (S, 2, 2, 3) int32 triangle vertices of p_u-, p_u+, p_v-, p_v+
    weights: np.ndarray  # (S, 2, 2, 3) float32 barycentric weights
    one_sided: np.ndarray  # (S, 2) bool: one end fell off the chart and is the sample itself
    uv_steps: np.ndarray  # (S, 2, 2) float64 uv distance of each end from the sample (0: off the chart)
    charts: np.ndarray  # (S,) int32 chart each sample searched in
    step: float  # cm on the neutral surface

    def __post_init__(self) -> None:
        s = len(self.samples)
        expected = {"vertices": (s, 2, 2, 3), "weights": (s, 2, 2, 3), "one_sided": (s, 2), "uv_steps": (s, 2, 2), "charts": (s,)}
        wrong = {name: np.shape(getattr(self, name)) for name, shape in expected.items() if np.shape(getattr(self, name)) != shape}
        if np.ndim(self.samples) != 1 or s == 0 or wrong:
            raise ValueError(f"neighbourhoods of {np.shape(self.samples)} samples need arrays shaped {expected}, got {wrong}")
        if np.min(self.vertices) < 0:
            raise ValueError("neighbourhood vertices must be vertex indices (>= 0)")

    @property
    def sample_count(self) -> int:
        return len(self.samples)

    @classmethod
    def build(cls, topology: Topology, uvs: UVs, neutral: np.ndarray, samples: np.ndarray, step: float = STEP_CM) -> "UVNeighbourhoods":
        """Find p_u+-, p_v+- for each sample: the points ±h along u (v) in its uv chart `step` cm away on the neutral."""
        neutral = np.asarray(neutral, dtype=np.float64)
        if neutral.ndim != 2 or neutral.shape[1] != 3:
            raise ValueError(f"neutral must be (N, 3) points, got shape {neutral.shape}")
        samples = np.asarray(samples)
        if samples.ndim != 1 or not np.issubdtype(samples.dtype, np.integer) or samples.size == 0:
            raise ValueError(f"samples must be a non-empty 1-D array of vertex indices, got shape {samples.shape} of {samples.dtype}")
        if samples.min() < 0 or samples.max() >= len(neutral):
            raise ValueError(f"samples must be vertex indices in [0, {len(neutral)}), got [{samples.min()}, {samples.max()}]")
        if not step > 0:
            raise ValueError(f"step must be a positive length in cm, got {step}")
        if topology.point_count > len(neutral):
            raise ValueError(f"topology uses vertex {topology.point_count - 1} but the neutral has {len(neutral)} points")
        mesh = _UVMesh(topology, uvs, neutral)
        uv_vertex = mesh.sample_uv_vertices(samples)
        chart = mesh.uv_vertex_chart[uv_vertex]
        speed = np.linalg.norm(mesh.uv_vertex_jacobians()[uv_vertex], axis=1)  # (S, 2) cm per uv unit
        if not np.all(speed > 0):
            bad = samples[~np.all(speed > 0, axis=1)]
            raise ValueError(f"samples {bad[:10].tolist()} have a degenerate uv map around them (no uv area)")
        s = len(samples)
        direction = np.zeros((s, 2, 2, 2))  # sample, direction (u, v), end (minus, plus), uv
        direction[:, 0, :, 0] = direction[:, 1, :, 1] = [-1.0, 1.0]
        h0 = np.broadcast_to((step / speed)[:, :, None], (s, 2, 2))
        origin = np.broadcast_to(mesh.uv_vertex_uv[uv_vertex][:, None, None, :], direction.shape)
        target = np.broadcast_to(neutral[samples][:, None, None, :], (s, 2, 2, 3))
        triangle, weights, uv_steps = _march(
            mesh, origin.reshape(-1, 2), direction.reshape(-1, 2), h0.ravel(), np.repeat(chart, 4), target.reshape(-1, 3), step
        )
        found = (triangle >= 0).reshape(s, 2, 2)
        lost = ~found.any(axis=2)
        if lost.any():
            bad = samples[lost.any(axis=1)]
            raise ValueError(
                f"samples {bad[:10].tolist()} have no point {step} cm away on either side in u or v "
                "within their uv chart; choose a smaller step or other samples"
            )
        vertices = np.where(found[..., None], mesh.triangles[triangle].reshape(s, 2, 2, 3), samples[:, None, None, None])
        weights = np.where(found[..., None], weights.reshape(s, 2, 2, 3), np.array([1.0, 0.0, 0.0]))
        return cls(
            samples=samples.astype(np.int32),
            vertices=vertices.astype(np.int32),
            weights=weights.astype(np.float32),
            one_sided=~found.all(axis=2),
            uv_steps=np.where(found, uv_steps.reshape(s, 2, 2), 0.0),
            charts=chart.astype(np.int32),
            step=float(step),
        )

    def compact(self) -> tuple[np.ndarray, "UVNeighbourhoods"]:
        """(the vertices stretch reads, these neighbourhoods indexing into them).

        Stretch reads a few thousand of a mesh's vertices; what is computed over frames before
        it (the expression shape's moving average) need only run on those columns, and gives
        the same stretch: points[:, used] with the compact neighbourhoods reads the same values.
        """
        used = np.unique(np.concatenate([self.samples.ravel(), self.vertices.ravel()]))
        position = np.zeros(int(used[-1]) + 1, np.int32)
        position[used] = np.arange(len(used), dtype=np.int32)
        return used, replace(self, samples=position[self.samples], vertices=position[self.vertices])

    def signed_weights(self) -> tuple[np.ndarray, np.ndarray]:
        """(S, 2, 6) vertices and weights with the minus end negated: D = sum_k w_k y[v_k] (weights sum to 0)."""
        s = self.sample_count
        signed = self.weights * np.array([-1.0, 1.0], np.float32)[None, None, :, None]
        return np.ascontiguousarray(self.vertices.reshape(s, 2, 6)), np.ascontiguousarray(signed.reshape(s, 2, 6), dtype=np.float32)


class _UVMesh:
    """The triangulated mesh in uv space, split into charts, with a uv point locator."""

    def __init__(self, topology: Topology, uvs: UVs, neutral: np.ndarray) -> None:
        import scipy.sparse as sp  # here, not with the module: facedyn.dynamics.samples reads STEP_CM without SciPy
        from scipy.sparse.csgraph import connected_components

        fvi = np.asarray(topology.face_vertex_indices, dtype=np.int64)
        corner_uv = _corner_uv_indices(fvi, uvs)
        corners = Topology(topology.face_vertex_counts, np.arange(len(fvi), dtype=np.int32)).triangles().astype(np.int64)
        values = np.asarray(uvs.values, dtype=np.float64)
        # A uv vertex is a (vertex, uv value) pair: seams split a vertex, equal uv values join corners.
        keys = np.column_stack([fvi, values[corner_uv]])
        unique, corner_uv_vertex = np.unique(keys, axis=0, return_inverse=True)
        corner_uv_vertex = corner_uv_vertex.ravel()
        self.uv_vertex_vertex = unique[:, 0].astype(np.int64)
        self.uv_vertex_uv = unique[:, 1:]
        self.triangles = fvi[corners]  # (T, 3) mesh vertices
        self.triangle_uv_vertices = corner_uv_vertex[corners]  # (T, 3)
        self.triangle_uv = self.uv_vertex_uv[self.triangle_uv_vertices]  # (T, 3, 2)
        self.neutral = neutral
        g = len(unique)
        t = self.triangle_uv_vertices
        edges = sp.coo_matrix((np.ones(3 * len(t)), (t.ravel(), np.roll(t, 1, axis=1).ravel())), shape=(g, g))
        _, self.uv_vertex_chart = connected_components(edges, directed=False)
        self.triangle_chart = self.uv_vertex_chart[t[:, 0]]
        edge1 = neutral[self.triangles[:, 1]] - neutral[self.triangles[:, 0]]
        edge2 = neutral[self.triangles[:, 2]] - neutral[self.triangles[:, 0]]
        self.area = 0.5 * np.linalg.norm(np.cross(edge1, edge2), axis=1)
        self._edges = np.stack([edge1, edge2], axis=2)  # (T, 3, 2)
        self.grid = _ChartGrid(self.triangle_uv, self.triangle_chart)

    def sample_uv_vertices(self, samples: np.ndarray) -> np.ndarray:
        """The uv vertex of each sample vertex with the most neutral area around it (its chart side)."""
        area = np.bincount(self.triangle_uv_vertices.ravel(), weights=np.repeat(self.area, 3), minlength=len(self.uv_vertex_vertex))
        order = np.lexsort((area, self.uv_vertex_vertex))  # by vertex, largest area last
        vertex = self.uv_vertex_vertex[order]
        last = np.r_[vertex[1:] != vertex[:-1], True]
        best = np.full(len(self.neutral), -1, np.int64)
        best[vertex[last]] = order[last]
        chosen = best[samples]
        if np.any(chosen < 0):
            raise ValueError(f"samples {samples[chosen < 0][:10].tolist()} belong to no polygon of the mesh")
        return chosen

    def uv_vertex_jacobians(self) -> np.ndarray:
        """(G, 3, 2) d(neutral position)/d(uv) at each uv vertex, area-weighted over its triangles."""
        duv = np.stack([self.triangle_uv[:, 1] - self.triangle_uv[:, 0], self.triangle_uv[:, 2] - self.triangle_uv[:, 0]], axis=2)
        det = np.linalg.det(duv)
        scale = np.max(np.abs(duv), axis=(1, 2)) ** 2
        ok = np.abs(det) > 1e-12 * np.maximum(scale, np.finfo(float).tiny)
        inverse = np.linalg.inv(np.where(ok[:, None, None], duv, np.eye(2)))
        jacobian = np.where(ok[:, None, None], self._edges @ inverse, 0.0) * self.area[:, None, None]
        total = np.zeros((len(self.uv_vertex_vertex), 3, 2))
        np.add.at(total, self.triangle_uv_vertices.ravel(), np.repeat(jacobian, 3, axis=0))
        weight = np.bincount(self.triangle_uv_vertices.ravel(), weights=np.repeat(self.area * ok, 3), minlength=len(total))
        return total / np.maximum(weight, np.finfo(float).tiny)[:, None, None]


class _ChartGrid:
    """Point-in-triangle search in uv, restricted to one chart per query point.

    A bucket grid per chart (cell = the chart's median triangle size) lists the triangles
    whose uv bounding box touches each cell, under one sorted integer key per (chart, cell);
    a query tests only the triangles of its own chart's cell, all queries at once.
    """

    def __init__(self, triangle_uv: np.ndarray, triangle_chart: np.ndarray) -> None:
        n_charts = int(triangle_chart.max()) + 1 if len(triangle_chart) else 0
        lo, hi = triangle_uv.min(axis=1), triangle_uv.max(axis=1)
        extent = (hi - lo).max(axis=1)
        per_chart = np.bincount(triangle_chart, minlength=n_charts)
        by_size = np.lexsort((extent, triangle_chart))
        middle = np.cumsum(per_chart) - per_chart + per_chart // 2
        cell = np.ones(n_charts)
        has = per_chart > 0
        cell[has] = extent[by_size[middle[has]]]
        cell[~(cell > 0)] = 1.0
        origin = np.zeros((n_charts, 2))
        origin[has] = np.inf
        np.minimum.at(origin, triangle_chart, lo)
        cell_lo = np.floor((lo - origin[triangle_chart]) / cell[triangle_chart, None]).astype(np.int64)
        cell_hi = np.floor((hi - origin[triangle_chart]) / cell[triangle_chart, None]).astype(np.int64)
        shape = np.zeros((n_charts, 2), np.int64)
        np.maximum.at(shape, triangle_chart, cell_hi + 1)
        span = cell_hi - cell_lo + 1
        covered = span[:, 0] * span[:, 1]
        tri = np.repeat(np.arange(len(triangle_uv)), covered)
        k = np.arange(covered.sum()) - np.repeat(np.cumsum(covered) - covered, covered)
        self._cell, self._origin, self._shape = cell, origin, shape
        self._base = np.concatenate([[0], np.cumsum(shape[:, 0] * shape[:, 1])[:-1]]).astype(np.int64)
        keys = self._key(triangle_chart[tri], cell_lo[tri, 0] + k // span[tri, 1], cell_lo[tri, 1] + k % span[tri, 1])
        order = np.argsort(keys, kind="stable")
        self._keys, self._triangles = keys[order], tri[order]
        self._triangle_uv = triangle_uv

    def _key(self, chart: np.ndarray, ix: np.ndarray, iy: np.ndarray) -> np.ndarray:
        return self._base[chart] + ix * self._shape[chart, 1] + iy

    def locate(self, points: np.ndarray, chart: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(Q,) triangle of `chart` that holds each uv point (-1: none) and (Q, 3) barycentrics."""
        q = np.floor((points - self._origin[chart]) / self._cell[chart, None]).astype(np.int64)
        inside = np.all((q >= 0) & (q < self._shape[chart]), axis=1)
        keys = self._key(chart, q[:, 0], q[:, 1])
        first = np.searchsorted(self._keys, keys, side="left")
        count = np.where(inside, np.searchsorted(self._keys, keys, side="right") - first, 0)
        query = np.repeat(np.arange(len(points)), count)
        candidate = self._triangles[np.repeat(first, count) + np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)]
        bary = _barycentric(points[query], self._triangle_uv[candidate])
        score = bary.min(axis=1)  # NaN for triangles without uv area: never a hit
        hit = score >= -_INSIDE
        query, candidate, bary, score = query[hit], candidate[hit], bary[hit], score[hit]
        best = np.lexsort((-score, query))  # per query, the most inside candidate first
        keep = best[np.r_[True, query[best][1:] != query[best][:-1]]] if len(best) else best
        triangle = np.full(len(points), -1, np.int64)
        weights = np.zeros((len(points), 3))
        triangle[query[keep]] = candidate[keep]
        inner = np.clip(bary[keep], 0.0, None)
        weights[query[keep]] = inner / inner.sum(axis=1, keepdims=True)
        return triangle, weights


def _march(mesh: _UVMesh, origin, direction, h, chart, target, step: float):
    """Walk along each uv ray to the point `step` cm from `target` on the neutral.

    The uv-to-surface scale varies quickly in places (near the lip edge a uv step several
    times longer than the Jacobian's covers the same 2 mm), so the Jacobian's h is only a
    first guess, refined by a search for distance(h) = step: rescale h by step / distance
    (halve it where the point left the chart) until an h too short and one too long are
    known, then bisect in log h. The point nearest `step` cm is kept when within
    _TOLERANCE of it; otherwise the end is off the chart (-1).
    Returns (Q,) triangles, (Q, 3) barycentrics, (Q,) uv distances.
    """
    best_triangle = np.full(len(h), -1, np.int64)
    best_weights = np.zeros((len(h), 3))
    best_h = np.zeros(len(h))
    best_error = np.full(len(h), np.inf)
    short, long = np.zeros(len(h)), np.full(len(h), np.inf)  # h known too short / too long (or off the chart)
    for _ in range(_MARCH_ITERATIONS):
        triangle, weights = mesh.grid.locate(origin + h[:, None] * direction, chart)
        found = triangle >= 0
        position = np.einsum("qk,qkc->qc", weights, mesh.neutral[mesh.triangles[triangle]])
        distance = np.where(found, np.linalg.norm(position - target, axis=1), np.inf)
        error = np.abs(distance / step - 1.0)
        better = error < best_error
        best_triangle[better], best_weights[better] = triangle[better], weights[better]
        best_h[better], best_error[better] = h[better], error[better]
        short = np.where(distance < step, np.maximum(short, h), short)
        long = np.where(distance >= step, np.minimum(long, h), long)
        with np.errstate(divide="ignore"):
            guess = np.where(found, h * step / distance, 0.5 * h)
        h = np.where((short > 0) & (long < np.inf), np.sqrt(short * long), guess)
    kept = best_error <= _TOLERANCE
    return np.where(kept, best_triangle, -1), best_weights, best_h


def _corner_uv_indices(fvi: np.ndarray, uvs: UVs) -> np.ndarray:
    """Index into uvs.values of every face-vertex corner, for faceVarying or vertex uvs."""
    n_values = len(uvs.values)
    if np.ndim(uvs.values) != 2 or np.shape(uvs.values)[1] != 2:
        raise ValueError(f"uv values must be (K, 2), got shape {np.shape(uvs.values)}")
    if uvs.interpolation == "faceVarying":
        corner = np.arange(len(fvi)) if uvs.indices is None else np.asarray(uvs.indices, dtype=np.int64)
        if len(corner) != len(fvi) or (uvs.indices is None and n_values != len(fvi)):
            raise ValueError(
                f"faceVarying uvs need one entry per face-vertex corner ({len(fvi)}), got {len(corner)} indices for {n_values} values"
            )
    elif uvs.interpolation in ("vertex", "varying"):
        corner = fvi if uvs.indices is None else np.asarray(uvs.indices, dtype=np.int64)[fvi]
    else:
        raise ValueError(f"uv interpolation must be faceVarying, vertex or varying for stretch, got {uvs.interpolation!r}")
    if corner.size and (corner.min() < 0 or corner.max() >= n_values):
        raise ValueError(f"uv indices must lie in [0, {n_values}), got [{corner.min()}, {corner.max()}]")
    return corner


def _barycentric(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(Q, 3) barycentric coordinates of 2-D points in 2-D triangles (NaN for degenerate ones)."""
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    v0, v1, v2 = b - a, c - a, points - a
    det = v0[:, 0] * v1[:, 1] - v0[:, 1] * v1[:, 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        beta = (v2[:, 0] * v1[:, 1] - v2[:, 1] * v1[:, 0]) / det
        gamma = (v0[:, 0] * v2[:, 1] - v0[:, 1] * v2[:, 0]) / det
    return np.stack([1.0 - beta - gamma, beta, gamma], axis=1)


def difference_lengths(points: np.ndarray, neighbourhoods: UVNeighbourhoods) -> np.ndarray:
    """(|D_u y_i|, |D_v y_i|) of one (N, 3) shape -> (S, 2), or of (F, N, 3) frames -> (F, S, 2)."""
    pts = _checked_points(points, neighbourhoods, allow_single=True)
    lengths = _lengths_numpy(pts.reshape((-1,) + pts.shape[-2:]), neighbourhoods)
    return lengths.reshape(pts.shape[:-2] + lengths.shape[1:])


def stretch_features(
    points: np.ndarray,
    neighbourhoods: UVNeighbourhoods,
    neutral_lengths: np.ndarray | None = None,
    backend: str = "auto",
) -> np.ndarray:
    """(F, S, 2) float32 stretch s_i(t) of eq. 8 for (F, N, 3) frames.

    `neutral_lengths` are |D_u|, |D_v| of the neutral, (S, 2) from `difference_lengths`;
    None measures them on frame 0. `backend` is 'auto', 'opencl' or 'numpy'
    (facedyn.kernels.runtime.choose_backend); both compute every frame at once.
    """
    if backend not in runtime.BACKENDS:
        raise ValueError(f"backend must be one of {runtime.BACKENDS}, got {backend!r}")
    pts = _checked_points(points, neighbourhoods, allow_single=False)
    if neutral_lengths is None:
        neutral_lengths = _lengths_numpy(pts[:1], neighbourhoods)[0]
    neutral_lengths = np.asarray(neutral_lengths, dtype=np.float32)
    if neutral_lengths.shape != (neighbourhoods.sample_count, 2):
        raise ValueError(f"neutral_lengths must be (S, 2) = ({neighbourhoods.sample_count}, 2), got shape {neutral_lengths.shape}")
    if not np.all(np.isfinite(neutral_lengths) & (neutral_lengths > 0)):
        raise ValueError("neutral_lengths must be positive and finite: the neutral has collapsed differences")
    chosen = runtime.choose_backend(backend, "stretch", _measure)
    impl = _stretch_opencl if chosen == "opencl" else _stretch_numpy
    return impl(pts, neighbourhoods, neutral_lengths)


def _checked_points(points: np.ndarray, neighbourhoods: UVNeighbourhoods, allow_single: bool) -> np.ndarray:
    pts = np.ascontiguousarray(points, dtype=np.float32)
    wanted = "(N, 3) or (F, N, 3)" if allow_single else "(F, N, 3)"
    if pts.ndim not in ((2, 3) if allow_single else (3,)) or pts.shape[-1] != 3:
        raise ValueError(f"points must be {wanted}, got shape {pts.shape}")
    needed = int(neighbourhoods.vertices.max()) + 1
    if pts.shape[-2] < needed:
        raise ValueError(f"points have {pts.shape[-2]} vertices but the neighbourhoods use vertex {needed - 1}")
    return pts


def _lengths_numpy(points: np.ndarray, neighbourhoods: UVNeighbourhoods) -> np.ndarray:
    """(F, S, 2) |D| for (F, N, 3) float32 points: one gather and one weighted sum for all frames.

    The signed weights sum to zero, so D = sum_k w_k (y[v_k] - y[i]) (short vectors only,
    as in stretch.cl: float32 never cancels two sums of large positions).
    """
    vertices, weights = neighbourhoods.signed_weights()
    centre = points[:, neighbourhoods.samples][:, :, None, None, :]
    difference = np.einsum("fsdkc,sdk->fsdc", points[:, vertices] - centre, weights)
    return np.sqrt(np.einsum("fsdc,fsdc->fsd", difference, difference))


def _stretch_numpy(points: np.ndarray, neighbourhoods: UVNeighbourhoods, neutral_lengths: np.ndarray) -> np.ndarray:
    return ((_lengths_numpy(points, neighbourhoods) - neutral_lengths) / neutral_lengths).astype(np.float32)


def _stretch_opencl(points: np.ndarray, neighbourhoods: UVNeighbourhoods, neutral_lengths: np.ndarray) -> np.ndarray:
    import pyopencl as cl

    rt = runtime.runtime()
    f, n = points.shape[:2]
    s = neighbourhoods.sample_count
    vertices, weights = neighbourhoods.signed_weights()
    mf = cl.mem_flags
    # A CPU device reads the frames where they lie (copying 1,000 ICT frames, 135 MB, would
    # take longer than the kernel); a GPU gets them copied into its own memory.
    frames_flag = mf.COPY_HOST_PTR if runtime.is_gpu() else mf.USE_HOST_PTR
    inputs = [cl.Buffer(rt.context, mf.READ_ONLY | frames_flag, hostbuf=points)] + [
        cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a)
        for a in (neighbourhoods.samples, vertices, weights, np.ascontiguousarray(neutral_lengths))
    ]
    out = np.empty((f, s, 2), np.float32)
    out_buf = cl.Buffer(rt.context, mf.WRITE_ONLY, out.nbytes)
    group = 64
    global_size = -(-f * s // group) * group
    kernel = cl.Kernel(runtime.program("stretch"), "stretch")  # a fresh kernel object per call: safe across threads
    kernel(rt.queue, (global_size,), (group,), *inputs, np.int32(f), np.int32(n), np.int32(s), out_buf)
    cl.enqueue_copy(rt.queue, out, out_buf)
    rt.queue.finish()
    return out


def _measure(backend: str) -> None:
    """The batch `choose_backend` times: 256 frames of 344 samples on a 4,000-point mesh."""
    rng = np.random.default_rng(0)
    n, s = 4000, 344
    samples = rng.choice(n, s, replace=False).astype(np.int32)
    weights = rng.dirichlet(np.ones(3), (s, 2, 2)).astype(np.float32)
    neighbourhoods = UVNeighbourhoods(
        samples=samples,
        vertices=rng.integers(0, n, (s, 2, 2, 3)).astype(np.int32),
        weights=weights,
        one_sided=np.zeros((s, 2), bool),
        uv_steps=np.full((s, 2, 2), 0.01),
        charts=np.zeros(s, np.int32),
        step=STEP_CM,
    )
    points = rng.normal(0.0, 5.0, (256, n, 3)).astype(np.float32)
    impl = _stretch_opencl if backend == "opencl" else _stretch_numpy
    impl(points, neighbourhoods, np.ones((s, 2), np.float32))
