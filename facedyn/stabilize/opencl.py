"""OpenCL twin of facedyn.stabilize.energy.NumpyEnergy (kernels/stabilize_energy.cl).

The NumPy evaluator makes about twenty whole-array passes per evaluation; the kernels
make three, with every per-vertex step fused in registers (float8), which is several
times faster even on PoCL's CPU device. Same inputs, same outputs; tests compare the
two. The context, queue and built program are the process's (facedyn.kernels.runtime).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from facedyn.kernels import runtime
from facedyn.stabilize.energy import Rebase, check_problem

PROGRAM = "stabilize_energy"
KERNELS = ("stabilize_points", "stabilize_velocity", "stabilize_gradient")
BLOCK = 128  # target vertices per work-item


def _band(velocity: sp.csr_matrix, frames: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Each row of the derivative operator as (first column, 7 contiguous weights)."""
    coo = velocity.tocoo()
    start = np.full(frames, frames, dtype=np.int64)
    np.minimum.at(start, coo.row, coo.col)
    start = np.where(start == frames, 0, start)
    offset = coo.col - start[coo.row]
    width = int(offset.max()) + 1 if coo.nnz else 1
    if width > 7:
        raise ValueError(f"the OpenCL kernel takes stencils of at most 7 frames, got {width}")
    stencil = np.zeros((frames, 7), dtype=np.float32)
    stencil[coo.row, offset] = coo.data
    return start.astype(np.int32), stencil, width


class OpenCLEnergy:
    """Energy evaluator with NumpyEnergy's interface, running the OpenCL kernels."""

    def __init__(self, points: np.ndarray, rest: np.ndarray, velocity: sp.spmatrix, weights: np.ndarray | None = None):
        import pyopencl as cl

        rt = runtime.runtime()
        self._cl, self._context, self._queue = cl, rt.context, rt.queue
        self._kernels = {name: runtime.kernel(PROGRAM, name) for name in KERNELS}
        points = check_problem(points, rest, velocity, weights)
        f, _, n = points.shape
        self.frames, self.count = f, n
        self.blocks = math.ceil(n / BLOCK)
        self.block = 8 * math.ceil(n / self.blocks / 8)
        self.padded = self.blocks * self.block
        self._host_points = np.zeros((f, 3, self.padded), dtype=np.float32)
        self._host_points[:, :, :n] = points
        self._moved = self._host_points.copy()
        self.base = Rebase(f)
        w = np.zeros(self.padded, dtype=np.float32)
        w[:n] = 1.0 if weights is None else weights
        velocity = sp.csr_matrix(velocity, dtype=np.float32)
        start, stencil, self.width = _band(velocity, f)
        dt = velocity.T.tocsr()
        self.with_velocity = int(f > 1 and velocity.nnz > 0)
        mf = cl.mem_flags
        ro = mf.READ_ONLY | mf.COPY_HOST_PTR

        def buffer(array):
            return cl.Buffer(self._context, ro, hostbuf=np.ascontiguousarray(array))

        self._points = buffer(self._moved)
        self._weights = buffer(w)
        self._start = buffer(start)
        self._stencil = buffer(stencil)
        self._dt_ptr = buffer(dt.indptr.astype(np.int32))
        self._dt_idx = buffer(dt.indices.astype(np.int32) if dt.nnz else np.zeros(1, np.int32))
        self._dt_val = buffer(dt.data.astype(np.float32) if dt.nnz else np.zeros(1, np.float32))
        padded_rest = np.zeros((3, self.padded), dtype=np.float32)
        padded_rest[:, :n] = rest
        self._rest = buffer(padded_rest)
        self._rt = cl.Buffer(self._context, mf.READ_ONLY, f * 12 * 4)
        self._grad_vel = cl.Buffer(self._context, mf.READ_WRITE, f * 3 * self.padded * 4)
        self._stabilized = cl.Buffer(self._context, mf.READ_WRITE, f * 3 * self.padded * 4)
        self._energy_host = np.empty((f, self.blocks), dtype=np.float32)
        self._energy = cl.Buffer(self._context, mf.WRITE_ONLY, self._energy_host.nbytes)
        self._out_host = np.empty((f, self.blocks, 13), dtype=np.float32)
        self._out = cl.Buffer(self._context, mf.WRITE_ONLY, self._out_host.nbytes)

    def rebase(self, rot: np.ndarray, trans: np.ndarray) -> None:
        """Store the points moved by (rot, trans), near which the next evaluations lie."""
        self.base.apply(self._host_points, rot, trans, self._moved)
        self._cl.enqueue_copy(self._queue, self._points, self._moved)

    def __call__(self, rot: np.ndarray, trans: np.ndarray, width_pos: float, width_vel: float, gradient: bool = True):
        """(position energy, velocity energy, dE/dR (F,3,3), dE/dt (F,3)); gradients None when not asked."""
        cl, queue, f = self._cl, self._queue, self.frames
        d_rot, d_trans = self.base.relative(rot, trans)
        rt = np.concatenate([d_rot.reshape(f, 9), d_trans], axis=1).astype(np.float32)
        cl.enqueue_copy(queue, self._rt, rt)
        size = (self.blocks, f)
        i32, f32 = np.int32, np.float32
        if self.with_velocity:
            self._kernels["stabilize_points"](
                queue, size, None, self._points, self._rt, i32(self.padded), i32(self.block), self._stabilized
            )
            self._kernels["stabilize_velocity"](
                queue, size, None,
                self._stabilized, self._start, self._stencil, self._weights,
                i32(self.padded), i32(self.width), i32(self.block),
                f32(width_vel), f32(4.0 / width_vel**2), self._grad_vel, self._energy,
            )  # fmt: skip
        self._kernels["stabilize_gradient"](
            queue, size, None,
            self._points, self._rt, self._rest, self._weights,
            self._dt_ptr, self._dt_idx, self._dt_val, self._grad_vel,
            i32(self.padded), i32(self.block), i32(self.with_velocity),
            f32(width_pos), f32(4.0 / width_pos**2), self._out,
        )  # fmt: skip
        cl.enqueue_copy(queue, self._out_host, self._out)
        e_vel = 0.0
        if self.with_velocity:
            cl.enqueue_copy(queue, self._energy_host, self._energy)
            e_vel = float(self._energy_host.sum(dtype=np.float64)) / width_vel**2
        sums = self._out_host.sum(axis=1, dtype=np.float64)
        e_pos = float(sums[:, 12].sum()) / width_pos**2
        if not gradient:
            return e_pos, e_vel, None, None
        grad = sums[:, :12].reshape(f, 3, 4)
        return e_pos, e_vel, self.base.absolute_gradient(grad[:, :, :3], grad[:, :, 3]), grad[:, :, 3]
