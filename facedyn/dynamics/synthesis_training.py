"""Training the synthesis network H (papers/000 §6), and calibrating it on one actor's takes.

Training (`train_synthesis`) needs, per take, the quasistatic skin y(t) and the captured
skin x(t), both in skull space; the targets are dY(t) = x(t) - y(t) at the samples. y(t)
comes either from a removal model F run on the takes, as the paper does, or straight from
the caller (e.g. the simulator's true quasistatic shapes). Settings as the paper: two
hidden layers of 256, ReLU, L2, Adam lr 1e-3, batches of 50 frames, about 30 epochs;
validation holds out whole takes. What H reads and how it is applied:
facedyn.dynamics.synthesis.
"""
from __future__ import annotations

import copy
from dataclasses import asdict, replace
from pathlib import Path
from typing import Iterable, Iterator, Mapping

import numpy as np
import torch

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.network import SYNTHESIS_HIDDEN, NetworkSpec, resolve_device
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.skull import check_points, check_transforms, skull_space
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.stretch import UVNeighbourhoods, difference_lengths, stretch_features
from facedyn.dynamics.synthesis import expression_shape, model_stretch, stretch_arrays
from facedyn.dynamics.training import (ProgressCallback, Resident, TrainConfig, fit, fit_new_network, offset_errors, split_store,
                                       store_takes, streamed_normalization)
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.performance import UVs

EPOCHS = 30
CALIBRATION_EPOCHS = 100  # a calibration session is a few minutes of frames: more passes over them
BATCH_FRAMES = 50


def synthesis_config(**changes) -> TrainConfig:
    """The paper's settings for H (30 epochs, batches of 50 frames) and facedyn's skull input
    (landmark accelerations, facedyn.dynamics.skull_motion), with any changes."""
    return TrainConfig(**{"epochs": EPOCHS, "batch_size": BATCH_FRAMES, "skull_motion": SkullMotionInput(), **changes})


class FrameSet(Resident):
    """Synthesis examples in memory, one per frame: input [skull features, S(t)], target dY(t) of all samples."""

    def __init__(self, inputs: np.ndarray, targets: np.ndarray, device: torch.device):
        self.inputs = torch.from_numpy(inputs).to(device)
        self.targets = torch.from_numpy(targets).to(device)

    def __len__(self) -> int:
        return len(self.inputs)

    def gather(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.inputs[idx], self.targets[idx]


def train_synthesis(
    takes: Iterable,
    face: FaceSetup,
    neighbourhoods: UVNeighbourhoods | UVs,
    quasistatic: DynamicsModel | Mapping[str, np.ndarray],
    config: TrainConfig | None = None,
    progress: ProgressCallback | None = None,
    backend: str = "auto",
    *,
    scratch: Path | str | None = None,
) -> DynamicsModel:
    """Train network H on the takes (TrainingSequence objects or dicts, any iterable) for the given face setup.

    neighbourhoods: the stretch neighbourhoods of ``face.samples`` on ``face.rest_points``,
    or the mesh's uvs to build them from (2 mm differences). quasistatic: where y(t) comes
    from, either a removal model (kind 'removal', the paper's way: y = F's quasistatic
    output on each take) or a mapping from take name to (F, N, 3) skull-space y(t) for
    every take. config defaults to `synthesis_config()`; frames within ``config.trim`` of
    a take's ends are left out, the validation takes are held out whole. ``backend``
    picks the stretch (and removal) kernels (facedyn.kernels.runtime.choose_backend).
    ``config.skull_motion`` is what H reads of the skull (synthesis_config's default:
    accelerations; None: the paper's B(t) over ``config.window``). The examples go to a
    store in ``scratch`` (facedyn.dynamics.training.train_removal says how).
    """
    config = config or synthesis_config()
    skull_motion = config.skull_motion or SkullMotionInput("velocity", config.window, config.window)
    source = _source_description(quasistatic)
    nb = _neighbourhoods(neighbourhoods, face)
    lengths = difference_lengths(face.rest_points.astype(np.float32), nb).astype(np.float32)
    device = resolve_device(config.device)
    store, described, fps = store_takes(takes, lambda take: _prepare(take, face, nb, lengths, quasistatic, config, backend, skull_motion), scratch)
    with store:
        _check_given_names(quasistatic, described)
        train, val = split_store(store, described, config, 1, lambda a: FrameSet(a["inputs"], a["targets"], device))
        names = [d["name"] for d in described if not d["validation"]]
        spec = NetworkSpec(store.columns["inputs"][0], SYNTHESIS_HIDDEN, store.columns["targets"][0])
        normalization = streamed_normalization(store, names, ("inputs",), "targets")
        network, curve = fit_new_network(spec, normalization, train, val, config, device, progress)
        errors = offset_errors(network, val, config.batch_size, "frames") if val is not None else None
    network.cpu()
    info = {
        "training": {
            "takes": described,
            "train_frames": len(train),
            "quasistatic_source": source,
            "config": _config_json(config),
            "device": str(device),
        },
        "validation": errors,
        "loss_curve": curve,
    }
    return DynamicsModel(
        kind="synthesis", network=network, face=face, fps=fps,
        windows={"stretch_smoothing": config.target_window}, info=info,
        arrays=stretch_arrays(nb, lengths), skull_motion=skull_motion,
    )


def calibrate_synthesis(
    model: DynamicsModel,
    takes: Iterable,
    quasistatic: DynamicsModel | Mapping[str, np.ndarray],
    config: TrainConfig | None = None,
    progress: ProgressCallback | None = None,
    backend: str = "auto",
    *,
    scratch: Path | str | None = None,
) -> DynamicsModel:
    """H trained further on one actor's own takes: a copy of ``model`` whose network goes on
    learning from them, with everything else it reads (samples, landmarks, stretch setup,
    skull input, normalization) kept.

    Why: H maps skull motion to the tissue's answer, and one H trained on a family of
    simulated tissues learns the family's average answer, which a given actor's tissue does
    not give (papers/000 trains H per actor, on that actor's captures through F). Calibration
    captures are the paper's kind: held expressions under motions such as platforms, walks
    and jumps; ``quasistatic`` is what gives their y(t) (a removal model F, or shapes by take
    name), as for `train_synthesis`. ``config`` defaults to `synthesis_config` with
    CALIBRATION_EPOCHS; its skull input is the model's.
    """
    if model.kind != "synthesis":
        raise ValueError(f"calibrate_synthesis needs a synthesis model, got a {model.kind!r} model")
    config = replace(config or synthesis_config(epochs=CALIBRATION_EPOCHS), skull_motion=model.skull_input)
    source = _source_description(quasistatic)
    nb, lengths = model_stretch(model)
    device = resolve_device(config.device)
    network = copy.deepcopy(model.torch_network()).to(device)
    store, described, fps = store_takes(takes, lambda take: _prepare(take, model.face, nb, lengths, quasistatic, config, backend, model.skull_input), scratch)
    with store:
        if abs(fps - model.fps) > 1e-6 * model.fps:
            raise ValueError(f"the takes run at {fps:g} fps, the synthesis model at {model.fps:g}; a model serves one rate")
        _check_given_names(quasistatic, described)
        train, val = split_store(store, described, config, 1, lambda a: FrameSet(a["inputs"], a["targets"], device))
        curve = fit(network, train, val, config, progress)
        errors = offset_errors(network, val, config.batch_size, "frames") if val is not None else None
    network.cpu()
    calibration = {"takes": described, "train_frames": len(train), "quasistatic_source": source, "device": str(device),
                   "config": _config_json(config), "loss_curve": curve}
    info = {**model.info, "calibration": calibration, "validation": errors}
    return DynamicsModel(kind="synthesis", network=network, face=model.face, fps=model.fps, windows=dict(model.windows), info=info,
                         arrays=dict(model.arrays), skull_motion=model.skull_input)


def _neighbourhoods(value, face: FaceSetup) -> UVNeighbourhoods:
    if isinstance(value, UVs):
        return UVNeighbourhoods.build(face.topology, value, face.rest_points, face.samples)
    if not isinstance(value, UVNeighbourhoods):
        raise ValueError(f"neighbourhoods must be UVNeighbourhoods or the mesh's UVs, got {type(value).__name__}")
    if not np.array_equal(value.samples, face.samples):
        raise ValueError("the stretch neighbourhoods were built for other skin samples than the face setup's")
    if value.vertices.max() >= face.point_count:
        raise ValueError(f"the stretch neighbourhoods use vertex {value.vertices.max()}, the face has {face.point_count}")
    return value


def _check_given_names(quasistatic, described: list[dict]) -> None:
    """Given quasistatic shapes must name only the takes (each take was checked to have its own as it came)."""
    if isinstance(quasistatic, Mapping):
        extra = sorted(set(quasistatic) - {d["name"] for d in described})
        if extra:
            raise ValueError(f"quasistatic shapes must be given for exactly the takes: not a take {extra}")


def _config_json(config: TrainConfig) -> dict:
    """The training settings as the model's info keeps them."""
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(config).items()}


def _source_description(quasistatic) -> dict:
    """Check the kind of quasistatic source (each take is checked against it as it comes); describe it for the model's info."""
    if isinstance(quasistatic, DynamicsModel):
        if quasistatic.kind != "removal":
            raise ValueError(f"quasistatic shapes come from a removal model, got a {quasistatic.kind!r} model")
        return {"kind": "removal", "topology_fingerprint": quasistatic.fingerprint, "validation": quasistatic.info.get("validation")}
    if not isinstance(quasistatic, Mapping):
        raise ValueError(f"quasistatic must be a removal model or a mapping of take names to shapes, got {type(quasistatic).__name__}")
    return {"kind": "given"}


def _prepare(take: TrainingSequence, face: FaceSetup, nb: UVNeighbourhoods, lengths: np.ndarray, quasistatic, config: TrainConfig, backend: str,
             skull_motion: SkullMotionInput) -> Iterator[dict[str, np.ndarray]]:
    """A take's frames away from its ends as store rows: inputs (skull features + 2S), targets (3S)."""
    pts = check_points(take.points, f"take {take.name!r} points")
    f = len(pts)
    if pts.shape[1] != face.point_count:
        raise ValueError(f"take {take.name!r} has {pts.shape[1]} points, the face setup {face.point_count}")
    if f <= 2 * config.trim:
        raise ValueError(f"take {take.name!r} has {f} frames, too few to leave out {config.trim} at each end")
    t, q = check_transforms(take.translate, take.orient, f)
    if isinstance(quasistatic, DynamicsModel):
        quasistatic.check_compatible(face.topology, take.fps)
        y, offsets = remove_dynamics(pts, t, q, take.fps, quasistatic, backend, space=take.space)
        targets = offsets[:, face.samples]
    else:
        if take.name not in quasistatic:
            raise ValueError(f"quasistatic shapes must be given for exactly the takes: missing {[take.name]}")
        y = np.asarray(quasistatic[take.name], dtype=np.float32)
        if y.shape != pts.shape:
            raise ValueError(f"take {take.name!r}: quasistatic shapes are {y.shape}, its points {pts.shape}")
        targets = skull_space(pts[:, face.samples], t, q, take.space) - y[:, face.samples]
    s = stretch_features(expression_shape(y, config.target_window), nb, lengths, backend)
    b = skull_motion.features(t, q, face.landmarks, take.fps)
    keep = slice(config.trim, f - config.trim)
    yield {"inputs": np.concatenate([b[keep], s[keep].reshape(f - 2 * config.trim, -1)], axis=1),
           "targets": targets[keep].reshape(f - 2 * config.trim, -1)}
