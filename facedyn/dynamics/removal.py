"""Removing secondary dynamics from a take with a trained network F (papers/000 eq. 7).

For every frame and skin sample, F(B(t), X_i(t)) (and the sample's rest position p_i, for a
model trained with it: ``skin_inputs``) predicts the dynamic offset dx_i(t), a skull-frame vector; Laplacian deformation spreads the sample offsets to every vertex
(facedyn.dynamics.propagate), and the quasistatic skin in skull space is

    T(t)^-1 y(t) = T(t)^-1 x(t) - dx(t)        (eq. 7, y = x - T(t) F, read in skull space)

Frames are processed in large chunks: features for the chunk in one batched call, the
network on all its (frame, sample) pairs at once with the skull-feature part of the first
layer computed once per frame (Network.forward_split), then one matrix product for the
propagation. No step loops over frames in Python.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from facedyn.dynamics.features import check_fps, compute_features
from facedyn.dynamics.modelfile import DynamicsModel, affordable_frames
from facedyn.dynamics.inference import network_runner
from facedyn.dynamics.skull import check_points, check_transforms, skull_space
from facedyn.dynamics.spikes import replace_spikes
from facedyn.geometry import quaternion

CHUNK_FRAMES = 128
SAMPLE_POSITIONS = "sample_positions"  # the model array of F's per-sample position input, when it reads one


def sample_positions(face) -> np.ndarray:
    """(S, 3) float32 rest positions of the face setup's skin samples, skull space."""
    return np.asarray(face.rest_points, dtype=np.float32)[face.samples]


def skin_inputs(skin: np.ndarray, positions: np.ndarray | None) -> np.ndarray:
    """F's per-sample inputs: the skin features X_i(t) (F, S, D), then p_i when F reads positions.

    Beyond the paper: one network serves every sample, and X_i(t) (velocities) does not say
    which sample it is looking at. The skull's acceleration differs over the face (the
    rotational part grows with the distance from the axis) and so does the tissue (softer
    on the cheeks than near the bone); the rest position tells F where the sample is.
    """
    if positions is None:
        return skin
    return np.concatenate([skin, np.broadcast_to(positions, skin.shape[:2] + (3,))], axis=-1)


def remove_dynamics(
    points,
    translate,
    orient,
    fps: float,
    model: DynamicsModel,
    backend: str = "auto",
    *,
    space: str = "skull",
    chunk_frames: int = CHUNK_FRAMES,
    device: str = "auto",
) -> tuple[np.ndarray, np.ndarray]:
    """(quasistatic skull-space points (F, N, 3), offsets (F, N, 3)), both float32.

    points: the captured skin, skull space (``space='skull'``, the stabilized layer's
    points) or world space (``'world'``); translate/orient: the skull T(t) (None =
    identity); fps: the take's rate, which must be the model's; backend: the features'
    ``'auto' | 'opencl' | 'numpy'``; device: where the network runs, ``'numpy'`` or a torch
    device (``'auto'``: a CUDA GPU if there is one, else NumPy). The offsets are
    skull-frame vectors, zero on the rigid region; quasistatic = skull points - offsets.
    A person-independent model set up for the take (facedyn.dynamics.portable.for_take)
    reads the take in its face frame; its offsets come back in the take's skull frame.
    """
    if model.frame is not None:
        return _remove_in_face_frame(points, translate, orient, fps, model, backend, space, chunk_frames, device)
    if model.kind != "removal":
        raise ValueError(f"remove_dynamics needs a removal model, got a {model.kind!r} model")
    pts = check_points(points)
    f, n = pts.shape[:2]
    if n != model.face.point_count:
        raise ValueError(f"the take has {n} points per frame, the model's mesh {model.face.point_count}")
    if space not in ("skull", "world"):
        raise ValueError(f"space must be 'skull' or 'world', got {space!r}")
    if int(chunk_frames) != chunk_frames or chunk_frames < 1:
        raise ValueError(f"chunk_frames must be a positive whole number, got {chunk_frames}")
    model.check_compatible(fps=check_fps(fps))
    t, q = check_transforms(translate, orient, f)
    skull_points = _to_skull32(pts, t, q) if space == "world" else np.asarray(pts, dtype=np.float32)
    # The samples in float64 from the input itself, so they lose nothing to the float32
    # skull-space copy above; F reads them with the tracker's spikes replaced.
    sample_points, _ = replace_spikes(skull_space(pts[:, model.face.samples], t, q, space))
    propagator = model.propagator()
    network = network_runner(model, device, split=True)
    window = model.windows["skull"]
    positions = model.arrays.get(SAMPLE_POSITIONS)
    if positions is not None and np.shape(positions) != (len(model.face.samples), 3):
        raise ValueError(f"the removal model's {SAMPLE_POSITIONS} are {np.shape(positions)}, not one 3-vector per skin sample "
                         f"({len(model.face.samples)})")
    # facedyn's skull input (model.skull_motion) replaces the kernel's B(t): a few numbers per frame
    skull = None if model.skull_motion is None else model.skull_motion.features(t, q, model.face.landmarks, fps)
    offsets = np.empty((f, n, 3), np.float32)
    step = affordable_frames(model, int(chunk_frames))
    for a in range(0, f, step):
        b = min(f, a + step)
        feats = compute_features(sample_points, t, q, model.face.landmarks, fps, space="skull", window=window, frame_range=(a, b), backend=backend)
        b_t = feats.skull if skull is None else skull[a:b]
        propagator.apply_into(network(b_t, skin_inputs(feats.skin, positions)), offsets[a:b])
    quasistatic = skull_points - offsets
    return quasistatic, offsets


def _remove_in_face_frame(points, translate, orient, fps, model, backend, space, chunk_frames, device):
    """remove_dynamics of a model set up for a take, in its face frame (facedyn.dynamics.portable)."""
    pts = check_points(points)
    t, q = check_transforms(translate, orient, len(pts))
    skull_points = skull_space(pts, t, q, space)
    t_face, q_face = model.frame.transforms(t, q)
    face_model = replace(model, frame=None, _propagator=model.propagator())
    _, offsets = remove_dynamics(model.frame.points(skull_points), t_face, q_face, fps, face_model, backend, space="skull",
                                 chunk_frames=chunk_frames, device=device)
    offsets = model.frame.vectors_back(offsets)
    return (skull_points - offsets).astype(np.float32), offsets


def _to_skull32(world: np.ndarray, t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """R^T (x - t) in float32 as one batched product ((x - t) as rows times R)."""
    rot = quaternion.to_matrix(q).astype(np.float32)
    return np.matmul(np.asarray(world, dtype=np.float32) - t[:, None, :].astype(np.float32), rot)
