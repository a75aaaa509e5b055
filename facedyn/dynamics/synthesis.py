"""Synthesizing secondary dynamics for a new skull motion with network H (papers/000 §6).

H maps the skull's motion (facedyn.dynamics.skull_motion: by default the landmarks'
accelerations over t-30..t+10, 615 numbers; the paper's B(t), the 315 landmark velocities
that removal also reads, on request) and the surface stretch S(t) of every skin sample
(facedyn.dynamics.stretch, eq. 8, measured on the quasistatic shape against the neutral)
to the dynamic offsets dY(t) of all samples jointly: one example per frame, input
skull + 2 S, output 3 S. Stretch tells H the expression, which changes how the tissue
moves; only the whole face's stretch says which expression it is, hence one joint network.
Training H is facedyn.dynamics.synthesis_training; the model file keeps everything
inference needs: the uv neighbourhoods and the neutral's difference lengths beside the
usual face setup (`stretch_arrays`, `model_stretch`).

Synthesis (`synthesize_dynamics`) runs on whole blocks of frames: the skull features of the
new skull motion, S(t) of the quasistatic shape, H, then the Laplacian propagation to every vertex
(facedyn.dynamics.propagate); the result is quasistatic + offsets, in skull space.
"""
from __future__ import annotations

import numpy as np

from facedyn.dynamics.features import check_fps
from facedyn.dynamics.modelfile import DynamicsModel, affordable_frames
from facedyn.dynamics.inference import network_runner
from facedyn.dynamics.response import is_linear_response, synthesized_dynamics
from facedyn.dynamics.skull import check_points, check_transforms
from facedyn.dynamics.stretch import UVNeighbourhoods, stretch_features
from facedyn.dynamics.targets import moving_average

CHUNK_FRAMES = 1024

# Model arrays (DynamicsModel.arrays) that hold the stretch setup; one_sided is stored as
# int32 because model files hold numbers only.
_STRETCH = "stretch/"


def synthesize_dynamics(
    quasistatic,
    translate,
    orient,
    fps: float,
    model: DynamicsModel,
    backend: str = "auto",
    *,
    chunk_frames: int = CHUNK_FRAMES,
    device: str = "auto",
) -> tuple[np.ndarray, np.ndarray]:
    """(points (F, N, 3) = quasistatic + offsets, offsets (F, N, 3)), float32, skull space.

    quasistatic: the dynamics-free skin y(t) in skull space; translate/orient: the new
    skull motion T(t) (None = identity); fps must be the model's; backend: the stretch
    kernel's ``'auto' | 'opencl' | 'numpy'``; device: where H runs, ``'numpy'`` or a torch device
    (``'auto'``: a CUDA GPU if there is one, else NumPy). Frames go
    through in blocks of ``chunk_frames`` (memory only: every step is batched over frames).
    """
    if model.kind not in ("synthesis", "response"):
        raise ValueError(f"synthesize_dynamics needs a synthesis model or a linear response, got a {model.kind!r} model")
    y = check_points(quasistatic, "quasistatic")
    f, n = y.shape[:2]
    if n != model.face.point_count:
        raise ValueError(f"the quasistatic take has {n} points per frame, the model's mesh {model.face.point_count}")
    if int(chunk_frames) != chunk_frames or chunk_frames < 1:
        raise ValueError(f"chunk_frames must be a positive whole number, got {chunk_frames}")
    model.check_compatible(fps=check_fps(fps))
    t, q = check_transforms(translate, orient, f)
    y = np.ascontiguousarray(y, dtype=np.float32)
    # a linear response reads no stretch, and its stiffening and expression term read neighbouring frames
    response = None
    if is_linear_response(model):
        b = model.skull_input.features(t, q, model.face.landmarks, fps)
        response = synthesized_dynamics(model, b, y[:, model.face.samples], fps)
    nb = lengths = shape = None
    if response is None:  # the expression shape on the vertices stretch reads only (the same stretch, a fifth of the work on ICT)
        nb, lengths = model_stretch(model)
        used, nb = nb.compact()
        shape = expression_shape(y[:, used], model.windows.get("stretch_smoothing", 0))
    propagator = model.propagator()
    network = None if response is not None else network_runner(model, device)
    samples = len(model.face.samples)
    offsets = np.empty((f, n, 3), np.float32)
    points = np.empty((f, n, 3), np.float32)
    step = affordable_frames(model, int(chunk_frames))
    for a in range(0, f, step):
        z = min(f, a + step)
        if response is not None:
            d = response[a:z]
        else:
            s = stretch_features(shape[a:z], nb, lengths, backend)
            b = model.skull_input.features(t, q, model.face.landmarks, fps, rows=(a, z))  # this chunk's windows only
            d = network(np.concatenate([b, s.reshape(z - a, -1)], axis=1)).reshape(z - a, samples, 3)
        propagator.apply_into(np.ascontiguousarray(d), offsets[a:z])
        np.add(y[a:z], offsets[a:z], out=points[a:z])
    return points, offsets


def expression_shape(quasistatic: np.ndarray, window: int) -> np.ndarray:
    """The quasistatic skin averaged over t-w..t+w: what stretch S(t) is measured on.

    Stretch is to tell H the expression. A quasistatic take made by F still holds some
    of the jiggle F missed, and H trained on its raw stretch learns to read the dynamics
    back out of it (a leak that vanishes on clean input, so H then predicts nothing); the
    expression itself changes slowly next to 6-11 Hz jiggle, so the average keeps it.
    """
    if window <= 0:
        return quasistatic
    return moving_average(quasistatic, window).astype(np.float32)


def stretch_arrays(neighbourhoods: UVNeighbourhoods, neutral_lengths: np.ndarray) -> dict[str, np.ndarray]:
    """The model arrays that rebuild the stretch features at inference (`model_stretch`)."""
    nb = neighbourhoods
    return {
        _STRETCH + "samples": nb.samples.astype(np.int32),
        _STRETCH + "vertices": nb.vertices.astype(np.int32),
        _STRETCH + "weights": nb.weights.astype(np.float32),
        _STRETCH + "one_sided": nb.one_sided.astype(np.int32),
        _STRETCH + "uv_steps": nb.uv_steps.astype(np.float64),
        _STRETCH + "charts": nb.charts.astype(np.int32),
        _STRETCH + "step": np.array([nb.step], np.float64),
        _STRETCH + "neutral_lengths": np.asarray(neutral_lengths, np.float32),
    }


def model_stretch(model: DynamicsModel) -> tuple[UVNeighbourhoods, np.ndarray]:
    """(neighbourhoods, neutral lengths (S, 2)) stored in a synthesis model."""
    arrays = {k[len(_STRETCH):]: v for k, v in model.arrays.items() if k.startswith(_STRETCH)}
    missing = {"samples", "vertices", "weights", "one_sided", "uv_steps", "charts", "step", "neutral_lengths"} - set(arrays)
    if missing:
        raise ValueError(f"the synthesis model lacks its stretch arrays {sorted(_STRETCH + m for m in missing)}")
    nb = UVNeighbourhoods(
        samples=arrays["samples"].astype(np.int32),
        vertices=arrays["vertices"].astype(np.int32),
        weights=arrays["weights"].astype(np.float32),
        one_sided=arrays["one_sided"].astype(bool),
        uv_steps=arrays["uv_steps"].astype(np.float64),
        charts=arrays["charts"].astype(np.int32),
        step=float(arrays["step"][0]),
    )
    if not np.array_equal(nb.samples, model.face.samples):
        raise ValueError("the synthesis model's stretch neighbourhoods belong to other skin samples than its face setup")
    if nb.vertices.max() >= model.face.point_count:
        raise ValueError(f"the stretch neighbourhoods use vertex {nb.vertices.max()}, the model's mesh has {model.face.point_count}")
    lengths = arrays["neutral_lengths"].astype(np.float32)
    if lengths.shape != (nb.sample_count, 2):
        raise ValueError(f"the model's neutral lengths must be ({nb.sample_count}, 2), got {lengths.shape}")
    return nb, lengths
