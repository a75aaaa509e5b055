"""The reference mode-pursuit stage solver: papers/001 as written, in PyTorch.

A forward function maps the control dual quaternions (the leaf tensor) through SDLB to
the stabilized mesh, velocities come from a 7-tap convolution (explicit stencils at the
ends), the fade penalty is the piecewise formula, autograd gives the gradient and
torch.optim.LBFGS (strong Wolfe line search) runs a fixed number of iterations per
stage. It is the yardstick for the fast solver's energies and speed, not for production.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import torch

from facedyn.stabilize.velocity import POINTS


def fade(u: torch.Tensor) -> torch.Tensor:
    """psi(u), n = 2, as written in papers/001 (u = |x| / w >= 0)."""
    return torch.where(u < 0.5, 2.0 * u * u, torch.where(u < 1.0, 1.0 - 2.0 * (1.0 - u) ** 2, torch.ones_like(u)))


def sdlb(basis: torch.Tensor, controls: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(R (F, 3, 3), t (F, 3)) of normalize(sum_i B_i q_i) with sign-aligned controls."""
    with torch.no_grad():
        dots = (controls[1:, :4] * controls[:-1, :4]).sum(-1)
        flips = torch.where(dots < 0, -1.0, 1.0).to(controls.dtype)
        signs = torch.cat([torch.ones(1, dtype=controls.dtype), torch.cumprod(flips, 0)])
    raw = basis @ (controls * signs[:, None])
    n = raw[:, :4].norm(dim=-1, keepdim=True)
    r = raw[:, :4] / n
    d = (raw[:, 4:] - r * (r * raw[:, 4:]).sum(-1, keepdim=True)) / n
    w, x, y, z = r.unbind(-1)
    rot = torch.stack(
        [
            torch.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            torch.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            torch.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    trans = 2.0 * (w[:, None] * d[:, 1:] - d[:, :1] * r[:, 1:] + torch.cross(r[:, 1:], d[:, 1:], dim=-1))
    return rot, trans


class TorchModel:
    """The energy of one chunk as a PyTorch function of the controls."""

    def __init__(self, points: np.ndarray, rest: np.ndarray, velocity: sp.spmatrix, weights: np.ndarray | None):
        dtype = torch.float32
        self.points = torch.from_numpy(np.ascontiguousarray(points, dtype=np.float32))  # (F, 3, N)
        self.rest = torch.from_numpy(np.array(rest, dtype=np.float32))
        self.weights = None if weights is None else torch.from_numpy(np.asarray(weights, dtype=np.float32))
        frames = self.points.shape[0]
        dense = np.asarray(sp.csr_matrix(velocity).todense())
        self.frames = frames
        if frames >= POINTS:
            # interior rows share one 7-tap kernel; the first and last 3 rows are explicit
            self.kernel = torch.tensor(dense[3, 0:POINTS], dtype=dtype).view(1, 1, POINTS)
            self.head = torch.tensor(dense[:3, :POINTS], dtype=dtype)
            self.tail = torch.tensor(dense[-3:, -POINTS:], dtype=dtype)
        else:
            self.dense = torch.tensor(dense, dtype=dtype)

    def velocity(self, s: torch.Tensor) -> torch.Tensor:
        flat = s.reshape(self.frames, -1)
        if self.frames < POINTS:
            return (self.dense @ flat).reshape(s.shape)
        inner = torch.nn.functional.conv1d(flat.T.unsqueeze(1), self.kernel).squeeze(1).T
        return torch.cat([self.head @ flat[:POINTS], inner, self.tail @ flat[-POINTS:]]).reshape(s.shape)

    def energy(self, basis: torch.Tensor, controls: torch.Tensor, width_pos: float, width_vel: float) -> torch.Tensor:
        rot, trans = sdlb(basis, controls)
        s = torch.einsum("fij,fjn->fin", rot, self.points) + trans[:, :, None]
        e_pos = fade((s - self.rest).abs() / width_pos)
        e_vel = fade(self.velocity(s).abs() / width_vel)
        total = e_pos + e_vel
        if self.weights is not None:
            total = total * self.weights
        return total.sum()


class ReferenceSolver:
    name = "reference"

    def bind(self, points: np.ndarray, rest: np.ndarray, velocity: sp.spmatrix, weights: np.ndarray | None):
        return TorchModel(points, rest, velocity, weights)

    def minimize(self, model: TorchModel, basis: sp.spmatrix, controls: np.ndarray, width_pos: float, width_vel: float,
                 iterations: int, memo: dict):
        """Run one stage; returns (controls (n, 8), final energy, energy evaluations).

        memo is unused: torch.optim.LBFGS starts every stage afresh, as in the paper.
        """
        b = torch.tensor(np.asarray(sp.csr_matrix(basis).todense()), dtype=torch.float32)
        # a flat leaf: LBFGS views every gradient as 1-D, which a matmul's transposed
        # gradient would not allow
        q = torch.tensor(np.asarray(controls, dtype=np.float32).ravel(), requires_grad=True)
        optimizer = torch.optim.LBFGS(
            [q],
            lr=1.0,
            max_iter=iterations,
            max_eval=25 * iterations,
            history_size=100,
            tolerance_grad=0.0,
            tolerance_change=0.0,
            line_search_fn="strong_wolfe",
        )
        evaluations = 0

        def closure():
            nonlocal evaluations
            evaluations += 1
            optimizer.zero_grad()
            loss = model.energy(b, q.view(-1, 8), width_pos, width_vel)
            loss.backward()
            return loss

        optimizer.step(closure)
        with torch.no_grad():
            final = float(model.energy(b, q.view(-1, 8), width_pos, width_vel))
        return q.detach().numpy().astype(np.float64).reshape(-1, 8), final, evaluations
