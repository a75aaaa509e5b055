"""Training the removal network F on held-expression takes (papers/000 §5.2).

Every (frame, skin sample) pair of every take is one example: input [B(t), X_i(t)]
(facedyn.dynamics.features), target the moving-average offset dx_i(t)
(facedyn.dynamics.targets). L2 loss, Adam, lr 1e-3, batches of 10,000 pairs; the paper
trains about 250 epochs.

Beyond the paper (its future work: "augmenting the corpus with physical simulation"), a
simulated corpus knows its true dynamics, and ``target="truth"`` trains on them instead.
The moving average only sees what changes within 21 frames (175 ms at 120 fps): it keeps
most of the slow, quasi-static response to walking and head turns, which the true
dynamics hold in full. Validation holds out whole takes, never frames of a training
take, because neighbouring frames of one take share most of their windows.

`fit` is the loop itself, written against any example set with ``len`` and
``gather(indices) -> (inputs, targets)``, so the synthesis network H (one example per
frame) trains through it as well.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Callable, Sequence

import numpy as np
import torch

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.features import WINDOW, check_fps, compute_features
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.network import Network, NetworkSpec, removal_spec, resolve_device
from facedyn.dynamics.skull import check_points, check_transforms, skull_space
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.targets import TARGET_WINDOW, dynamic_offsets
from facedyn.performance import Performance

TARGETS = ("moving-average", "truth")
ProgressCallback = Callable[[int, float, "float | None"], None]  # (epoch, train loss, val loss) in cm^2


@dataclass
class Take:
    """One training take as arrays: the whole mesh, its skull T(t) and frame rate."""

    name: str
    points: np.ndarray  # (F, N, 3) skull space (space="skull") or world space ("world")
    fps: float
    translate: np.ndarray | None = None  # (F, 3); None = identity
    orient: np.ndarray | None = None  # (F, 4) (w, x, y, z); None = identity
    space: str = "skull"
    dynamics: np.ndarray | None = None  # (F, N, 3) known secondary dynamics, skull frame (a simulated take's truth)

    @classmethod
    def coerce(cls, value) -> "Take":
        """A Take from a Take or a dict with the same keys."""
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            unknown = set(value) - set(cls.__dataclass_fields__)
            if unknown:
                raise ValueError(f"unknown take keys {sorted(unknown)}; a take has {sorted(cls.__dataclass_fields__)}")
            return cls(**value)
        raise ValueError(f"a take must be a Take or a dict, got {type(value).__name__}")

    @classmethod
    def from_performance(cls, performance: Performance, name: str) -> "Take":
        t, q = performance.skull()
        return cls(name, performance.points, performance.fps, t, q, "skull")


@dataclass
class TrainConfig:
    epochs: int = 250
    batch_size: int = 10_000
    learning_rate: float = 1e-3
    subsample: float = 1.0  # fraction of the training pairs drawn (afresh) each epoch
    trim: int = TARGET_WINDOW  # frames left out at each end of a take (clamped targets)
    window: int = WINDOW  # feature half-window w_b = w_x
    target_window: int = TARGET_WINDOW  # moving-average half-window w
    validation: tuple[str, ...] | None = None  # held-out take names; None = the last take if >= 2
    max_validation_pairs: int = 200_000  # per epoch's validation loss (a fixed subset)
    seed: int = 0
    device: str = "auto"  # "auto" = cuda when available, else cpu
    target: str = "moving-average"  # F's targets: "moving-average" (the paper) or "truth" (Take.dynamics)
    skull_motion: SkullMotionInput | None = None  # skull features; None = the paper's B(t) over `window`

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise ValueError(f"target must be one of {TARGETS}, got {self.target!r}")
        if self.epochs < 1 or self.batch_size < 1 or self.max_validation_pairs < 1:
            raise ValueError("epochs, batch_size and max_validation_pairs must be at least 1")
        if not 0 < self.subsample <= 1:
            raise ValueError(f"subsample must be a fraction in (0, 1], got {self.subsample}")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        if self.trim < 0:
            raise ValueError(f"trim must be a non-negative number of frames, got {self.trim}")


class PairSet:
    """Removal examples: (frame, sample) pairs with input [B(t), X_i(t)] and target dx_i(t)."""

    def __init__(self, skull: np.ndarray, skin: np.ndarray, targets: np.ndarray, frames: np.ndarray, device: torch.device):
        self.samples = skin.shape[1]
        self.skull = torch.from_numpy(skull).to(device)
        self.skin = torch.from_numpy(skin).to(device)
        self.targets = torch.from_numpy(targets).to(device)
        self.frames = torch.from_numpy(frames.astype(np.int64)).to(device)

    def __len__(self) -> int:
        return len(self.frames) * self.samples

    def gather(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        f = self.frames[idx // self.samples]
        s = idx % self.samples
        return torch.cat([self.skull[f], self.skin[f, s]], dim=1), self.targets[f, s]


def fit(network: Network, train, val, config: TrainConfig, progress: ProgressCallback | None = None) -> list[dict]:
    """Adam on the L2 loss in normalized units; returns the loss curve in cm^2 per coordinate.

    The network must already carry its normalization (the loss is reported as the mean
    squared offset error, i.e. the normalized loss times output_scale^2).
    """
    device = next(network.parameters()).device
    generator = torch.Generator().manual_seed(config.seed)
    optimizer = torch.optim.Adam(network.parameters(), lr=config.learning_rate, foreach=True)
    scale2 = float(network.output_scale) ** 2
    val_idx = None
    if val is not None and len(val):
        val_idx = torch.randperm(len(val), generator=generator)[: config.max_validation_pairs].to(device)
    curve = []
    for epoch in range(1, config.epochs + 1):
        network.train()
        count = max(1, int(round(config.subsample * len(train))))
        order = torch.randperm(len(train), generator=generator)[:count].to(device)
        total = 0.0
        for start in range(0, count, config.batch_size):
            x, y = train.gather(order[start: start + config.batch_size])
            loss = torch.mean((network.normalized(x) - network.normalize_targets(y)) ** 2)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(x)
        train_loss = total / count * scale2
        val_loss = None if val_idx is None else mean_squared_error(network, val, val_idx, config.batch_size)
        curve.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss})
        if progress is not None:
            progress(epoch, train_loss, val_loss)
    network.eval()
    return curve


def fit_new_network(spec: NetworkSpec, normalization, train, val, config: TrainConfig, device: torch.device,
                    progress: ProgressCallback | None = None) -> tuple[Network, list[dict]]:
    """A network initialized from ``config.seed`` (without touching the global RNG), fitted."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        network = Network(spec)
    network.set_normalization(*normalization)
    network.to(device)
    return network, fit(network, train, val, config, progress)


@torch.no_grad()
def mean_squared_error(network: Network, examples, idx: torch.Tensor, batch_size: int) -> float:
    """Mean squared offset error per coordinate (cm^2) over the examples ``idx``."""
    network.eval()
    total = 0.0
    for start in range(0, len(idx), batch_size):
        x, y = examples.gather(idx[start: start + batch_size])
        total += float(torch.sum((network(x) - y) ** 2)) / y.shape[1]
    return total / len(idx)


@torch.no_grad()
def validation_errors(network: Network, examples: PairSet, batch_size: int) -> dict:
    """Offset errors over every validation pair, in cm, beside doing nothing (zero offsets)."""
    network.eval()
    dist, truth = [], []
    idx = torch.arange(len(examples), device=examples.frames.device)
    for start in range(0, len(idx), batch_size):
        x, y = examples.gather(idx[start: start + batch_size])
        dist.append(torch.linalg.norm(network(x) - y, dim=1).cpu())
        truth.append(torch.linalg.norm(y, dim=1).cpu())
    dist, truth = torch.cat(dist).double(), torch.cat(truth).double()
    return {
        "pairs": len(examples),
        "rms_cm": float(torch.sqrt(torch.mean(dist**2))),
        "mean_cm": float(torch.mean(dist)),
        "max_cm": float(torch.max(dist)),
        "zero_offset_rms_cm": float(torch.sqrt(torch.mean(truth**2))),
    }


def _prepare(take: Take, face: FaceSetup, config: TrainConfig, backend: str):
    pts = check_points(take.points, f"take {take.name!r} points")
    if pts.shape[1] != face.point_count:
        raise ValueError(f"take {take.name!r} has {pts.shape[1]} points, the face setup {face.point_count}")
    f = len(pts)
    if f <= 2 * config.trim:
        raise ValueError(f"take {take.name!r} has {f} frames, too few to leave out {config.trim} at each end")
    t, q = check_transforms(take.translate, take.orient, f)
    samples = skull_space(pts[:, face.samples], t, q, take.space)
    feats = compute_features(samples, t, q, face.landmarks, take.fps, space="skull", window=config.window, backend=backend)
    skull = feats.skull if config.skull_motion is None else config.skull_motion.features(t, q, face.landmarks, take.fps)
    if config.target == "truth":
        if take.dynamics is None:
            raise ValueError(f"take {take.name!r} has no known dynamics to train on (target 'truth' needs a simulated corpus)")
        dynamics = np.asarray(take.dynamics)
        if dynamics.shape != pts.shape:
            raise ValueError(f"take {take.name!r}: dynamics are {dynamics.shape}, its points {pts.shape}")
        targets = dynamics[:, face.samples].astype(np.float32)
    else:
        targets = dynamic_offsets(samples, space="skull", window=config.target_window).astype(np.float32)
    return skull, feats.skin, targets, np.arange(config.trim, f - config.trim)


def _pairs(prepared: list, device: torch.device) -> PairSet | None:
    if not prepared:
        return None
    offset, frames = 0, []
    for skull, _, _, valid in prepared:
        frames.append(valid + offset)
        offset += len(skull)
    return PairSet(
        np.concatenate([p[0] for p in prepared]),
        np.concatenate([p[1] for p in prepared]),
        np.concatenate([p[2] for p in prepared]),
        np.concatenate(frames),
        device,
    )


def split_takes(takes: Sequence, validation: Sequence[str] | None) -> tuple[list[Take], float, set[str]]:
    """(takes as Take objects, their one frame rate, the names held out for validation)."""
    takes = [Take.coerce(t) for t in takes]
    if not takes:
        raise ValueError("training needs at least one take")
    rates = {t.name: check_fps(t.fps) for t in takes}
    fps = rates[takes[0].name]
    if any(abs(r - fps) > 1e-6 * fps for r in rates.values()):
        raise ValueError(f"takes run at different frame rates {rates}; a model is trained for one rate")
    return takes, fps, _split(takes, validation)


def _split(takes: list[Take], validation: Sequence[str] | None) -> set[str]:
    names = [t.name for t in takes]
    if len(set(names)) != len(names):
        raise ValueError(f"take names must be unique, got {names}")
    if validation is None:
        return {names[-1]} if len(names) >= 2 else set()
    held = set(validation)
    missing = held - set(names)
    if missing:
        raise ValueError(f"validation takes {sorted(missing)} are not among the takes {names}")
    if held >= set(names):
        raise ValueError("every take is held out for validation; nothing is left to train on")
    return held


def _normalization(train: PairSet, max_pairs: int = 1_000_000, seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Feature and target statistics from up to `max_pairs` random training pairs.

    A large corpus holds tens of millions of pairs; their statistics are settled long
    before that, and a float64 copy of all of them would not fit in memory.
    """
    frames = train.frames.cpu().numpy()
    rng = np.random.default_rng(seed)
    pick = rng.choice(len(train), size=min(len(train), max_pairs), replace=False)
    f, s = frames[pick // train.samples], pick % train.samples
    skull = train.skull.cpu().numpy()[np.unique(frames)].astype(np.float64)
    skin = train.skin.cpu().numpy()[f, s].astype(np.float64)
    targets = train.targets.cpu().numpy()[f, s].astype(np.float64)
    mean = np.concatenate([skull.mean(axis=0), skin.mean(axis=0)])
    std = np.concatenate([skull.std(axis=0), skin.std(axis=0)])
    out_mean = targets.mean(axis=0)
    return mean, std, out_mean, float(np.sqrt(np.mean((targets - out_mean) ** 2)))


def train_removal(
    takes: Sequence,
    face: FaceSetup,
    config: TrainConfig | None = None,
    progress: ProgressCallback | None = None,
    backend: str = "auto",
) -> DynamicsModel:
    """Train network F on the takes (Take objects or dicts) for the given face setup.

    All takes must share one frame rate (the model's). Frames within ``config.trim`` of a
    take's ends are left out (their targets average over clamped windows). ``backend``
    picks the feature implementation (facedyn.kernels.runtime.choose_backend).
    """
    config = config or TrainConfig()
    takes, fps, held = split_takes(takes, config.validation)
    device = resolve_device(config.device)
    prepared = {t.name: _prepare(t, face, config, backend) for t in takes}
    train = _pairs([prepared[t.name] for t in takes if t.name not in held], device)
    val = _pairs([prepared[t.name] for t in takes if t.name in held], device)
    del prepared  # the pair sets hold their own copies; a large corpus cannot afford both

    spec: NetworkSpec = removal_spec(train.skull.shape[1], train.skin.shape[2])
    network, curve = fit_new_network(spec, _normalization(train), train, val, config, device, progress)
    errors = validation_errors(network, val, config.batch_size) if val is not None else None
    network.cpu()
    info = {
        "training": {
            "takes": [{"name": t.name, "frames": int(len(t.points)), "space": t.space, "validation": t.name in held} for t in takes],
            "train_pairs": len(train),
            "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(config).items()},
            "device": str(device),
        },
        "validation": errors,
        "loss_curve": curve,
    }
    windows = {"skull": config.window, "skin": config.window, "target": config.target_window}
    return DynamicsModel(kind="removal", network=network, face=face, fps=fps, windows=windows, info=info, skull_motion=config.skull_motion)
