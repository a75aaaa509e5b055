"""The removal network's inputs: skull features B(t) and skin features X_i(t) (papers/000 §5.1).

Both are windows of velocities in the skull ("canonical") frame, so that the absolute head
pose never enters the network:

- skull landmark l at frame k, eq. (2):
  ``bdot_l(k) = (I - T(k)^-1 T(k-1)) b_l / dt``
  ``         = ((I - R_k^T R_{k-1}) b_l + R_k^T (t_k - t_{k-1})) / dt``,
  i.e. the landmark's world velocity over the frame pair (k-1, k), rotated into the skull
  frame of k. b_l is in skull space.
- skin sample i at frame k, eq. (4):
  ``xdot_i(k) = (T(k)^-1 x_i(k) - T(k-1)^-1 x_i(k-1)) / dt``,
  the velocity of the skull-space position (motion relative to the skull).
- eqs. (1) and (3): ``B(t) = [bdot_1(t-w..t+w), ..., bdot_L(t-w..t+w)]`` (landmark-major,
  then window entry, then x, y, z: L * (2w+1) * 3 = 315 for L = 5, w = 10) and
  ``X_i(t) = [xdot_i(t-w..t+w)]`` ((2w+1) * 3 = 63). Every window entry k uses its own
  frame pair (k-1, k) in the frame of k, as eq. (2) defines bdot(k) for any k; the window
  is not re-expressed in the frame of the centre frame t.

dt = 1 / fps. Ends: indices are clamped to [0, F-1], so a pair that leaves the sequence
repeats a frame and its velocity is exactly zero: bdot(k) = xdot(k) = 0 for k <= 0 and
k >= F (frame 0 has no predecessor). Features of frames near the ends therefore see a head
and skin at rest beyond the take.

Two backends compute the same arrays: NumPy in float64 (the reference) and the OpenCL
kernel ``facedyn/kernels/features.cl`` in float32, one launch for all frames, samples
and landmarks. Both return float32. The kernel reads the points as float32, as USD
stores them (point3f); float64 world points far from the origin lose their low bits in
that cast, so pass such points to the kernel in skull space or use the NumPy backend.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.dynamics.skull import check_points, check_transforms, to_skull
from facedyn.geometry import quaternion
from facedyn.kernels import runtime

WINDOW = 10
_TABLE = 36  # floats per frame in the kernel's frame table (see features.cl)


@dataclass
class Features:
    """B(t) and X_i(t) of a run of frames."""

    skull: np.ndarray  # (F, L * (2w+1) * 3) float32, B(t)
    skin: np.ndarray  # (F, S, (2w+1) * 3) float32, X_i(t)


def check_fps(fps) -> float:
    fps = float(fps)
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be a positive frame rate, got {fps}")
    return fps


def _check_window(window) -> int:
    if int(window) != window or window < 0:
        raise ValueError(f"window must be a non-negative whole number of frames, got {window}")
    return int(window)


def _check_landmarks(landmarks) -> np.ndarray:
    b = np.asarray(landmarks, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 3 or len(b) == 0:
        raise ValueError(f"skull landmarks must be (L, 3) skull-space points, got {b.shape}")
    return b


def _pair_transforms(translate: np.ndarray, orient: np.ndarray) -> dict[str, np.ndarray]:
    """Per-frame terms of the pair (k-1, k), float64, zero at k = 0 (no predecessor).

    ``skull_rotation`` and ``skull_translation`` are the parts of I - T(k)^-1 T(k-1);
    the others are the pieces of the rearranged skin velocity used by the kernel.
    """
    f = len(translate)
    rt = np.swapaxes(quaternion.to_matrix(orient), 1, 2)
    rot = np.swapaxes(rt, 1, 2)
    out = {name: np.zeros((f, 3, 3)) for name in ("skull_rotation", "rt_change")}
    out.update({name: np.zeros((f, 3)) for name in ("skull_translation", "t_change", "t_previous")})
    out["rt"] = rt
    dt = translate[1:] - translate[:-1]
    out["skull_rotation"][1:] = np.eye(3) - rt[1:] @ rot[:-1]
    out["skull_translation"][1:] = np.einsum("kij,kj->ki", rt[1:], dt)
    out["rt_change"][1:] = rt[1:] - rt[:-1]
    out["t_change"][1:] = dt
    out["t_previous"][1:] = translate[:-1]
    return out


def windows(velocities: np.ndarray, window: int) -> np.ndarray:
    """(F, ..., 3) per-frame velocities -> (F, ..., (2w+1)*3) windows t-w..t+w, zero outside."""
    return span_windows(velocities, window, window)


def span_windows(values: np.ndarray, past: int, future: int, rows: tuple[int, int] | None = None) -> np.ndarray:
    """(F, ..., 3) per-frame vectors -> (F, ..., (past+future+1)*3) windows t-past..t+future, zero outside.

    rows (a, z): the windows of frames a..z-1 only.
    """
    a, z = (0, len(values)) if rows is None else rows
    padded = np.pad(values, [(past, future)] + [(0, 0)] * (values.ndim - 1))
    width = past + future + 1
    idx = np.arange(a, z)[:, None] + np.arange(width)[None, :]  # (z - a, width) into padded
    win = np.moveaxis(padded[idx], 1, -2)  # (F, ..., width, 3)
    return win.reshape(win.shape[:-2] + (width * 3,))


def skull_velocities(translate, orient, landmarks, fps) -> np.ndarray:
    """(F, L, 3) bdot_l(k) of eq. (2), float64; zero at k = 0."""
    t, q = check_transforms(translate, orient)
    b = _check_landmarks(landmarks)
    pairs = _pair_transforms(t, q)
    v = np.einsum("kij,lj->kli", pairs["skull_rotation"], b) + pairs["skull_translation"][:, None, :]
    return v * check_fps(fps)


def skin_velocities(skull_points, fps) -> np.ndarray:
    """(F, S, 3) xdot_i(k) of eq. (4) from skull-space positions, float64; zero at k = 0."""
    p = check_points(skull_points, "skull_points").astype(np.float64)
    v = np.zeros_like(p)
    v[1:] = (p[1:] - p[:-1]) * check_fps(fps)
    return v


def _numpy_features(points, t, q, landmarks, fps, window, space) -> Features:
    skull_points = to_skull(points, t, q) if space == "world" else points.astype(np.float64)
    b = windows(skull_velocities(t, q, landmarks, fps).astype(np.float32), window)
    x = windows(skin_velocities(skull_points, fps).astype(np.float32), window)
    return Features(skull=b.reshape(len(b), -1), skin=x)


def _frame_table(t, q, space) -> np.ndarray:
    pairs = _pair_transforms(t, q)
    f = len(t)
    table = np.zeros((f, _TABLE))
    if space == "world":
        table[:, 0:9] = pairs["rt"].reshape(f, 9)
        table[:, 9:18] = pairs["rt_change"].reshape(f, 9)
        table[:, 18:21] = pairs["t_change"]
        table[:, 21:24] = pairs["t_previous"]
    else:  # the points are already T(k)^-1 x(k): identity for the skin terms
        table[:, 0:9] = np.eye(3).ravel()
    table[:, 24:33] = pairs["skull_rotation"].reshape(f, 9)
    table[:, 33:36] = pairs["skull_translation"]
    return table.astype(np.float32)


def _opencl_features(points, t, q, landmarks, fps, window, space) -> Features:
    import pyopencl as cl

    rt = runtime.runtime()
    knl = cl.Kernel(runtime.program("features"), "windowed_velocities")  # per call: safe across threads
    f, s = points.shape[:2]
    n_landmarks = len(landmarks)
    width = 2 * window + 1
    mf = cl.mem_flags
    pts = np.ascontiguousarray(points, dtype=np.float32)
    table = _frame_table(t, q, space)
    lms = np.ascontiguousarray(landmarks, dtype=np.float32)
    skin = np.empty((f, s, width * 3), np.float32)
    skull = np.empty((f, n_landmarks * width * 3), np.float32)
    # OpenCL rejects zero-sized buffers: size every buffer at least one float.
    bufs = [cl.Buffer(rt.context, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=a if a.size else np.zeros(1, np.float32))
            for a in (pts, table, lms)]
    out_skin = cl.Buffer(rt.context, mf.WRITE_ONLY, max(skin.nbytes, 4))
    out_skull = cl.Buffer(rt.context, mf.WRITE_ONLY, max(skull.nbytes, 4))
    total = f * (s + n_landmarks)
    group = 64
    global_size = ((total + group - 1) // group) * group
    knl(
        rt.queue, (global_size,), (group,), *bufs,
        np.int32(f), np.int32(s), np.int32(n_landmarks), np.int32(window), np.float32(fps),
        out_skin, out_skull,
    )
    if skin.size:
        cl.enqueue_copy(rt.queue, skin, out_skin)
    cl.enqueue_copy(rt.queue, skull, out_skull)
    rt.queue.finish()
    return Features(skull=skull, skin=skin)


def _measure(backend: str) -> None:
    """The batch `choose_backend` times: 64 frames of 344 samples, a moving skull."""
    rng = np.random.default_rng(0)
    f = 64
    t = np.cumsum(rng.normal(0, 0.1, (f, 3)), axis=0)
    q = quaternion.from_rotvec(np.cumsum(rng.normal(0, 0.01, (f, 3)), axis=0))
    pts = rng.normal(0, 5, (f, 344, 3)).astype(np.float32)
    impl = _opencl_features if backend == "opencl" else _numpy_features
    impl(pts, t, q, rng.normal(0, 5, (5, 3)), 120.0, WINDOW, "world")


def compute_features(
    points,
    translate,
    orient,
    landmarks,
    fps: float,
    *,
    space: str = "skull",
    window: int = WINDOW,
    frame_range: tuple[int, int] | None = None,
    backend: str = "auto",
) -> Features:
    """B(t) and X_i(t) for the frames in ``frame_range`` (default: all).

    points: (F, S, 3) skin samples, skull space (``space='skull'``, the stabilized points)
    or world space (``space='world'``); translate/orient: the skull T(t) (None = identity);
    landmarks: (L, 3) skull-space skull landmarks; backend: ``'auto' | 'opencl' | 'numpy'``
    (facedyn.kernels.runtime.choose_backend). A frame range reads only the frames its
    windows need, so a long take can be processed in chunks with results identical to
    the whole take's.
    """
    pts = check_points(points)
    if space not in ("skull", "world"):
        raise ValueError(f"space must be 'skull' or 'world', got {space!r}")
    t, q = check_transforms(translate, orient, len(pts))
    b = _check_landmarks(landmarks)
    fps = check_fps(fps)
    window = _check_window(window)
    f = len(pts)
    start, stop = (0, f) if frame_range is None else (int(frame_range[0]), int(frame_range[1]))
    if not 0 <= start < stop <= f:
        raise ValueError(f"frame_range must satisfy 0 <= start < stop <= {f}, got {frame_range}")
    # Frames t in [start, stop) read pairs (k-1, k) for k in [t-w, t+w]; outside [0, F)
    # those velocities are zero whether or not the sequence is cut here.
    lo, hi = max(0, start - window - 1), min(f, stop + window)
    chosen = runtime.choose_backend(backend, "features", _measure)
    impl = _opencl_features if chosen == "opencl" else _numpy_features
    out = impl(pts[lo:hi], t[lo:hi], q[lo:hi], b, fps, window, space)
    return Features(skull=out.skull[start - lo: stop - lo], skin=out.skin[start - lo: stop - lo])
