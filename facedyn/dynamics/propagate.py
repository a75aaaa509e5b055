"""Spread offsets known at the skin samples to every vertex by Laplacian mesh deformation.

The paper propagates sample offsets with its Anatomical Local Model and names Laplacian
mesh deformation (Sorkine et al. 2004) as the alternative; facedyn uses the latter. The
offset field u (N x 3) minimizes the bi-Laplacian energy

    E(u) = sum_i |(L u)_i|^2 / m_i  =  u^T L M^-1 L u       (discrete integral of |lap u|^2)

with L the cotangent Laplacian and M the lumped (Voronoi) mass of the rest mesh, subject
to hard constraints: u = the given offset at every sample, u = 0 on the rigid region.
Vertices in a piece of mesh with no constraint at all stay at 0 as well. The minimizer is
linear in the sample offsets, u = P d, so the (N x S) propagation matrix P is solved once
per topology (one sparse factorization, all S right-hand sides together) and applying it
is a dense matrix product over many frames at once, in float32.

`Propagator.residual` reports sqrt(E) per frame, evaluated with the batched sparse
Laplacian (OpenCL kernel ``facedyn/kernels/laplacian.cl`` or its SciPy twin), as the
smoothness check of propagated offsets.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from facedyn.dynamics import propagator_cache
from facedyn.geometry.mesh import cotangent_laplacian, unique_edges, vertex_areas
from facedyn.kernels import runtime

if TYPE_CHECKING:
    import scipy.sparse as sp

    from facedyn.dynamics.spread import Spread

_APPLY_CHUNK = 64  # frames per matrix product


class RestOperators:
    """The rest mesh's Laplacian, masses and fixed vertices, each built when first asked for.

    Solving P needs all three, the smoothness check the first two; applying a P read from
    the cache needs none, so a command that only applies a model neither builds them nor
    imports SciPy.
    """

    def __init__(self, points: np.ndarray, triangles, samples: np.ndarray, rigid: np.ndarray):
        self.points, self.triangles, self.samples, self.given_rigid = points, triangles, samples, rigid

    @cached_property
    def laplacian(self) -> sp.csr_matrix:
        return cotangent_laplacian(self.points, self.triangles)

    @cached_property
    def inverse_mass(self) -> np.ndarray:
        area = vertex_areas(self.points, self.triangles)
        return np.where(area > 0, 1.0 / np.where(area > 0, area, 1.0), 0.0)

    @cached_property
    def fixed(self) -> np.ndarray:
        """(N,) True where u = 0: the given rigid vertices and pieces of mesh with no constraint."""
        n = len(self.points)
        fixed = np.zeros(n, bool)
        fixed[self.given_rigid] = True
        fixed |= _unconstrained(n, self.triangles, np.concatenate([self.samples, self.given_rigid]))
        fixed[self.samples] = False
        return fixed


@dataclass
class Propagator:
    matrix: np.ndarray  # (N, S) float32, P
    samples: np.ndarray  # (S,) int32
    operators: RestOperators = field(repr=False)
    spread: Spread | None = field(default=None, repr=False)  # an actor's learned correction (facedyn.dynamics.spread), added to P d

    @property
    def rigid(self) -> np.ndarray:
        """(R,) int32 vertices held at zero (including unconstrained pieces)."""
        return np.flatnonzero(self.operators.fixed).astype(np.int32)

    @property
    def laplacian(self) -> sp.csr_matrix:
        """(N, N) cotangent Laplacian of the rest mesh."""
        return self.operators.laplacian

    @property
    def inverse_mass(self) -> np.ndarray:
        """(N,) 1 / m_i (0 for vertices in no triangle)."""
        return self.operators.inverse_mass

    def apply(self, offsets) -> np.ndarray:
        """(F, S, 3) sample offsets -> (F, N, 3) float32 offsets of every vertex."""
        d = np.asarray(offsets, dtype=np.float32)
        s = self.matrix.shape[1]
        if d.ndim != 3 or d.shape[1:] != (s, 3):
            raise ValueError(f"sample offsets must be (frames, {s}, 3), got {d.shape}")
        out = np.empty((len(d), self.matrix.shape[0], 3), np.float32)
        self.apply_into(d, out)
        return out

    def apply_into(self, offsets: np.ndarray, out: np.ndarray) -> None:
        """Write P d (plus the spread's correction, if any) for (F, S, 3) float32 offsets into a
        preallocated (F, N, 3) float32 array.

        Frames go through in chunks: one (chunk * 3, S) x (S, N) product each (BLAS, P read
        transposed in place), whose rows are a frame's x, y and z over every vertex, so each
        frame is reordered to (N, 3) from three contiguous rows rather than from columns a
        chunk apart (a sixth less time at 11,248 points).
        """
        n, s = self.matrix.shape
        d = np.asarray(offsets, dtype=np.float32)
        for a in range(0, len(d), _APPLY_CHUNK):
            chunk = d[a: a + _APPLY_CHUNK]
            f = len(chunk)
            product = chunk.transpose(0, 2, 1).reshape(f * 3, s) @ self.matrix.T
            out[a: a + f] = product.reshape(f, 3, n).transpose(0, 2, 1)
            if self.spread is not None:
                self.spread.add_into(chunk, out[a: a + f])

    def residual(self, offsets, backend: str = "auto") -> np.ndarray:
        """(F,) sqrt(sum_i |(L u)_i|^2 / m_i) of (F, N, 3) offsets: the energy minimized."""
        lu = laplacian_apply(self.laplacian, offsets, backend)
        energy = np.einsum("fnc,fnc,n->f", lu, lu, self.inverse_mass.astype(np.float32))
        return np.sqrt(energy)


def build_propagator(rest_points, triangles, samples, rigid=None, cache: bool = False) -> Propagator:
    """P for a rest mesh, its sample vertices and its rigid vertices (default: none).

    cache: take P from the on-disk cache of solved matrices and keep it there when solved
    (facedyn.dynamics.propagator_cache): the same P, without the solve on a later run.
    """
    pts = np.asarray(rest_points, dtype=np.float64)
    n = len(pts)
    samples = np.asarray(samples, dtype=np.int64)
    rigid = np.zeros(0, np.int64) if rigid is None else np.asarray(rigid, dtype=np.int64)
    for name, idx in (("samples", samples), ("rigid vertices", rigid)):
        if idx.ndim != 1 or (idx.size and (idx.min() < 0 or idx.max() >= n)):
            raise ValueError(f"{name} must be 1-D vertex indices in [0, {n})")
    if samples.size == 0 or len(np.unique(samples)) != len(samples):
        raise ValueError("propagation needs at least one sample and distinct sample vertices")
    if np.intersect1d(samples, rigid).size:
        raise ValueError("a vertex cannot be both a sample and rigid")
    operators = RestOperators(pts, triangles, samples, rigid)
    cache_key = propagator_cache.key(pts, triangles, samples, rigid) if cache else None
    matrix = propagator_cache.load(cache_key, samples, n) if cache else None
    if matrix is None:
        is_sample = np.zeros(n, bool)
        is_sample[samples] = True
        free = np.flatnonzero(~operators.fixed & ~is_sample)
        matrix = _solve(operators.laplacian, operators.inverse_mass, samples, free, n)
        if cache:
            propagator_cache.keep(cache_key, matrix)
    return Propagator(matrix=matrix, samples=samples.astype(np.int32), operators=operators)


def _solve(lap: sp.csr_matrix, inv_mass: np.ndarray, samples: np.ndarray, free: np.ndarray, n: int) -> np.ndarray:
    """(N, S) float32 P: the identity at the samples, solved at the free vertices, 0 elsewhere."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import splu

    p = np.zeros((n, len(samples)))
    p[samples, np.arange(len(samples))] = 1.0
    if free.size:
        q = (lap.T @ sp.diags(inv_mass) @ lap).tocsr()
        q_free = q[free][:, free].tocsc()
        rhs = -(q[free][:, samples]).toarray()
        p[free] = splu(q_free).solve(rhs)  # COLAMD ordering: the fastest of SuperLU's here
    return p.astype(np.float32)


def _unconstrained(n: int, triangles, constrained: np.ndarray) -> np.ndarray:
    """(N,) True for vertices whose connected piece of mesh holds no constrained vertex."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    edges = unique_edges(triangles)
    graph = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    held = np.zeros(labels.max() + 1, bool)
    held[labels[constrained]] = True
    return ~held[labels]


def _numpy_apply(csr: sp.csr_matrix, u: np.ndarray) -> np.ndarray:
    f, n, _ = u.shape
    rhs = np.ascontiguousarray(u.transpose(1, 0, 2)).reshape(n, f * 3)
    return np.ascontiguousarray((csr @ rhs).reshape(n, f, 3).transpose(1, 0, 2))


def _opencl_apply(csr: sp.csr_matrix, u: np.ndarray) -> np.ndarray:
    import pyopencl as cl

    rt = runtime.runtime()
    knl = cl.Kernel(runtime.program("laplacian"), "csr_apply_frames")  # per call: safe across threads
    f, n, _ = u.shape
    mf = cl.mem_flags
    arrays = (
        np.ascontiguousarray(csr.indptr, dtype=np.int32),
        np.ascontiguousarray(csr.indices, dtype=np.int32) if csr.nnz else np.zeros(1, np.int32),
        np.ascontiguousarray(csr.data, dtype=np.float32) if csr.nnz else np.zeros(1, np.float32),
        np.ascontiguousarray(u, dtype=np.float32),
    )
    bufs = [cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a) for a in arrays]
    out = np.empty((f, n, 3), np.float32)
    out_buf = cl.Buffer(rt.context, mf.WRITE_ONLY, out.nbytes)
    group = 64
    total = f * n
    knl(rt.queue, (((total + group - 1) // group) * group,), (group,), *bufs, np.int32(n), np.int32(f), out_buf)
    cl.enqueue_copy(rt.queue, out, out_buf)
    rt.queue.finish()
    return out


def _measure(backend: str) -> None:
    """The batch `choose_backend` times: a 2,500-vertex grid Laplacian on 64 frames."""
    import scipy.sparse as sp

    side = 50
    lap = sp.diags([-1.0, -1.0, 4.0, -1.0, -1.0], [-side, -1, 0, 1, side], shape=(side * side, side * side)).tocsr()
    u = np.random.default_rng(0).normal(size=(64, side * side, 3)).astype(np.float32)
    (_opencl_apply if backend == "opencl" else _numpy_apply)(lap.astype(np.float32), u)


def laplacian_apply(laplacian, u, backend: str = "auto") -> np.ndarray:
    """L @ u[f] for every frame: (N, N) sparse L, (F, N, 3) u -> (F, N, 3) float32."""
    import scipy.sparse as sp

    csr = sp.csr_matrix(laplacian, dtype=np.float32)
    arr = np.asarray(u, dtype=np.float32)
    n = csr.shape[0]
    if csr.shape != (n, n):
        raise ValueError(f"the Laplacian must be square, got {csr.shape}")
    if arr.ndim != 3 or arr.shape[1:] != (n, 3):
        raise ValueError(f"u must be (frames, {n}, 3), got {arr.shape}")
    if len(arr) == 0:
        return np.zeros((0, n, 3), np.float32)
    chosen = runtime.choose_backend(backend, "laplacian", _measure)
    return (_opencl_apply if chosen == "opencl" else _numpy_apply)(csr, arr)
