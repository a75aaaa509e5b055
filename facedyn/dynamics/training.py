"""Training the removal network F on held-expression takes (papers/000 §5.2).

Every (frame, skin sample) pair of every take is one example: input [B(t), X_i(t)]
(facedyn.dynamics.features; with ``sample_positions`` also the sample's rest position p_i),
target the moving-average offset dx_i(t) (facedyn.dynamics.targets). L2 loss, Adam, lr 1e-3, batches of 10,000 pairs; the paper
trains about 250 epochs. Beyond the paper, a batch's pairs come in pieces of 16 samples of
one frame (PairSet.batches), so the skull features are put through the first layer once
per piece rather than once per pair: the same loss, a third of the arithmetic.

Beyond the paper (its future work: "augmenting the corpus with physical simulation"), a
simulated corpus knows its true dynamics, and ``target="truth"`` trains on them instead.
The moving average only sees what changes within 21 frames (175 ms at 120 fps): it keeps
most of the slow, quasi-static response to walking and head turns, which the true
dynamics hold in full. Validation holds out whole takes, never frames of a training
take, because neighbouring frames of one take share most of their windows.

Takes are prepared one at a time into an on-disk store (facedyn.dynamics.store) and
training streams its examples back in chunks of bounded size, so the memory training
needs does not grow with the corpus. `fit` is the loop itself, written against example
sets with ``chunks`` of resident sets that have ``len`` and ``gather(indices) -> (inputs,
targets)``, so the synthesis network H (one example per frame) trains through it as well.
"""
from __future__ import annotations

import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable, Iterator, Sequence

import numpy as np
import torch

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.features import WINDOW, check_fps, skin_velocities, skull_velocities, span_windows
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.network import Network, NetworkSpec, removal_spec, resolve_device
from facedyn.dynamics.removal import SAMPLE_POSITIONS, sample_positions
from facedyn.dynamics.skull import check_points, check_transforms, skull_space
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.spikes import replace_spikes
from facedyn.dynamics.store import KEPT, WINDOW_INDEX, StreamedExamples, TrainingStore
from facedyn.dynamics.targets import TARGET_WINDOW, dynamic_offsets
from facedyn.dynamics.training_sequence import TrainingSequence

TARGETS = ("moving-average", "truth")
PIECE_SAMPLES = 16  # skin samples of one frame that train together in a batch (PairSet.batches)
PREPARE_FRAMES = 1024  # frames of one take whose features are computed (and held) at once
ProgressCallback = Callable[[int, float, "float | None"], None]  # (epoch, train loss, val loss) in cm^2


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
    target: str = "moving-average"  # F's targets: "moving-average" (the paper) or "truth" (TrainingSequence.dynamics)
    skull_motion: SkullMotionInput | None = None  # skull features; None = the paper's B(t) over `window`
    sample_positions: bool = False  # F also reads each skin sample's rest position (facedyn.dynamics.removal.skin_inputs)
    resident_bytes: int = 1 << 30  # examples held in memory at once; a larger corpus streams from its store in chunks
    time_limit_s: float | None = None  # stop before an epoch that would end past this many seconds from the trainer's start

    def __post_init__(self) -> None:
        if self.target not in TARGETS:
            raise ValueError(f"target must be one of {TARGETS}, got {self.target!r}")
        if self.epochs < 1 or self.batch_size < 1 or self.max_validation_pairs < 1 or self.resident_bytes < 1:
            raise ValueError("epochs, batch_size, max_validation_pairs and resident_bytes must be at least 1")
        if not 0 < self.subsample <= 1:
            raise ValueError(f"subsample must be a fraction in (0, 1], got {self.subsample}")
        if not self.learning_rate > 0:
            raise ValueError(f"learning_rate must be positive, got {self.learning_rate}")
        if self.time_limit_s is not None and not self.time_limit_s > 0:
            raise ValueError(f"time_limit_s must be positive seconds, got {self.time_limit_s}")
        if self.trim < 0:
            raise ValueError(f"trim must be a non-negative number of frames, got {self.trim}")


class Resident:
    """An example set held in memory: one chunk, evaluated whole (see StreamedExamples).

    Subclasses have ``len`` and ``gather(indices) -> (inputs, targets)``; training draws
    its batches through ``batches`` and predicts them with ``normalized``, which a set may
    override to batch its examples in a cheaper shape (PairSet).
    """

    def chunks(self, generator: torch.Generator | None = None):
        yield self

    def subset(self, max_examples: int, generator: torch.Generator):
        return self

    def batches(self, subsample: float, batch_size: int, generator: torch.Generator, device: torch.device):
        """(inputs, targets) batches over a random `subsample` of the examples, drawn afresh from `generator`."""
        count = max(1, int(round(subsample * len(self))))
        order = torch.randperm(len(self), generator=generator)[:count].to(device)
        for start in range(0, count, batch_size):
            yield self.gather(order[start: start + batch_size])

    def normalized(self, network: Network, inputs) -> torch.Tensor:
        """The network's normalized output for a batch's inputs (what the loss compares)."""
        return network.normalized(inputs)


class PairSet(Resident):
    """Removal examples in memory: every (frame, sample) pair, input [B(t), X_i(t)(, p_i)], target dx_i(t).

    X_i(t) is put together when a batch is gathered, from the frames' skin velocities and
    each frame's window of them (TrainingStore.read_windows), never stored whole. Training
    batches pair frames with pieces of PIECE_SAMPLES samples (`batches`), so the network
    computes a frame's skull part once per piece (Network.normalized_split).
    """

    def __init__(self, skull: np.ndarray, velocities: np.ndarray, window: np.ndarray, targets: np.ndarray,
                 positions: np.ndarray | None, device: torch.device):
        """skull (F, Ds); velocities (V, S, 3) skin velocities of the frames the windows read;
        window (F, 2w + 1) each frame's window into them; targets (F, S, 3); positions (F, S, 3) or None."""
        self.samples = velocities.shape[1]
        self.skull = torch.from_numpy(skull).to(device)
        runs, self.run_start = _window_runs(torch.from_numpy(velocities).to(device),
                                            torch.from_numpy(np.ascontiguousarray(window, np.int64)).to(device))
        self.run_rows = runs.shape[1]
        self.windows = runs.view(-1).unfold(0, window.shape[1] * 3, 3)  # row r: the 2w + 1 velocities from flat row r of runs
        self.targets = torch.from_numpy(targets).to(device)
        self.positions = None if positions is None else torch.from_numpy(np.asarray(positions, np.float32)).to(device)

    def __len__(self) -> int:
        return len(self.skull) * self.samples

    def skin(self, f: torch.Tensor, s: torch.Tensor) -> torch.Tensor:
        """(B, Di) skin inputs of pairs (f, s): the window of velocities, then the rest position.

        A pair's window is one run of the sample's rows of `runs` (_window_runs), read as a
        single row of an overlapping view: a gather per pair, not one per frame of its window.
        """
        x = self.windows.index_select(0, self.run_start.index_select(0, f) + s * self.run_rows)
        return x if self.positions is None else torch.cat([x, self._pairs(self.positions, f * self.samples + s)], dim=1)

    @staticmethod
    def _pairs(values: torch.Tensor, pairs: torch.Tensor) -> torch.Tensor:
        """values (F, S, 3) at flat pair indices f * S + s."""
        return values.view(-1, values.shape[-1]).index_select(0, pairs)

    def gather(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        f = idx // self.samples
        s = idx % self.samples
        return torch.cat([self.skull.index_select(0, f), self.skin(f, s)], dim=1), self._pairs(self.targets, idx)

    def batches(self, subsample: float, batch_size: int, generator: torch.Generator, device: torch.device):
        """((skull (U, Ds), skin (B, Di), frame of each pair (B,)), targets (B, 3)) batches.

        Each frame gives a random `subsample` of its samples (drawn afresh every epoch),
        cut into pieces of PIECE_SAMPLES; the pieces of all frames are shuffled and batches
        of `batch_size` pairs taken in that order. A batch of 2,000 pairs therefore spans
        about 125 frames, not 2,000: the skull part, most of F's inputs, is computed 16
        times less often (Network.normalized_split), and a batch still sees many frames.
        """
        frames, samples = len(self.skull), self.samples
        per_frame = min(samples, max(1, int(round(subsample * samples))))
        kept = torch.rand(frames, samples, generator=generator).argsort(dim=1)[:, :per_frame].reshape(-1).to(device)
        order = _piece_order(torch.randperm(frames * -(-per_frame // PIECE_SAMPLES), generator=generator), per_frame).to(device)
        for start in range(0, len(order), batch_size):
            picked = order[start: start + batch_size]  # pair k is sample kept[k] of frame k // per_frame
            f, s = picked // per_frame, kept.index_select(0, picked)
            unique, rows = torch.unique(f, return_inverse=True)
            yield (self.skull.index_select(0, unique), self.skin(f, s), rows), self._pairs(self.targets, f * samples + s)

    def normalized(self, network: Network, inputs) -> torch.Tensor:
        return network.normalized_split(*inputs)


def _window_runs(velocities: torch.Tensor, window: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(runs (S, R, 3), start (F,)) with runs[s, start[k] + j] = velocities[window[k, j], s].

    velocities (V, S, 3), window (F, 2w + 1). A window of consecutive rows (a frame whose
    window lies inside its take) starts at its first row; any other (one reaching past the
    take's ends into the zero row) gets a copy of its rows, appended after the V. Sample by
    sample, every window is then one run of 2w + 1 rows, which PairSet.skin gathers as one.
    """
    span = window.shape[1]
    regular = (window == window[:, :1] + torch.arange(span, device=window.device)).all(dim=1)
    copies = window[~regular].reshape(-1)
    start = torch.where(regular, window[:, 0], len(velocities) + (torch.cumsum(~regular, 0) - 1) * span)
    runs = velocities.transpose(0, 1)
    if len(copies):
        runs = torch.cat([runs, runs.index_select(1, copies)], dim=1)
    return runs.contiguous(), start


def _piece_order(rank: torch.Tensor, per_frame: int) -> torch.Tensor:
    """The pairs (k: the kept sample k % per_frame of frame k // per_frame) piece by piece,
    pieces in the order of their `rank`, a piece's pairs in order.

    Pieces are runs of PIECE_SAMPLES pairs of a frame (its last one shorter); piece q of
    frame f is number f * pieces + q. The same order as a stable argsort of every pair's
    piece rank, built in linear time from the inverse permutation instead of sorting.
    """
    pieces = -(-per_frame // PIECE_SAMPLES)
    by_rank = torch.empty_like(rank)
    by_rank[rank] = torch.arange(len(rank))
    first = by_rank // pieces * per_frame + by_rank % pieces * PIECE_SAMPLES
    lengths = (per_frame - by_rank % pieces * PIECE_SAMPLES).clamp_(max=PIECE_SAMPLES)
    return torch.repeat_interleave(first - (torch.cumsum(lengths, 0) - lengths), lengths) + torch.arange(int(lengths.sum()))


def fit(network: Network, train, val, config: TrainConfig, progress: ProgressCallback | None = None,
        deadline: float | None = None) -> list[dict]:
    """Adam on the L2 loss in normalized units; returns the loss curve in cm^2 per coordinate.

    With a `deadline` (a time.monotonic() value) training stops after the epoch that leaves
    less time than it took itself: the learning rate is constant, so fewer epochs are the
    same training cut short (the epochs then depend on the machine's speed).

    train and val are example sets with ``chunks`` and ``subset``: resident ones
    (PairSet, synthesis.FrameSet) or StreamedExamples from a TrainingStore. Each epoch
    shuffles within every chunk (a resident set: all of it, as one permutation). The
    network must already carry its normalization (the loss is reported as the mean squared
    offset error, i.e. the normalized loss times output_scale^2).
    """
    device = next(network.parameters()).device
    generator = torch.Generator().manual_seed(config.seed)
    optimizer = torch.optim.Adam(network.parameters(), lr=config.learning_rate, foreach=True)
    scale2 = float(network.output_scale) ** 2
    checked = None if val is None or not len(val) else val.subset(config.max_validation_pairs, generator)
    curve = []
    for epoch in range(1, config.epochs + 1):
        began = time.monotonic()
        network.train()
        total, drawn = 0.0, 0
        for chunk in train.chunks(generator):
            for x, y in chunk.batches(config.subsample, config.batch_size, generator, device):
                loss = torch.mean((chunk.normalized(network, x) - network.normalize_targets(y)) ** 2)
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                count = y.numel() // y.shape[-1]
                total += float(loss.detach()) * count
                drawn += count
            del chunk, x, y  # the next chunk loads into this one's memory
        train_loss = total / drawn * scale2
        val_loss = None if checked is None else _mean_squared_error(network, checked, config.batch_size)
        curve.append({"epoch": epoch, "train_loss": train_loss, "val_loss": val_loss})
        if progress is not None:
            progress(epoch, train_loss, val_loss)
        now = time.monotonic()
        if deadline is not None and now + (now - began) > deadline:
            break
    network.eval()
    return curve


def fit_new_network(spec: NetworkSpec, normalization, train, val, config: TrainConfig, device: torch.device,
                    progress: ProgressCallback | None = None, deadline: float | None = None) -> tuple[Network, list[dict]]:
    """A network initialized from ``config.seed`` (without touching the global RNG), fitted."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        network = Network(spec)
    network.set_normalization(*normalization)
    network.to(device)
    return network, fit(network, train, val, config, progress, deadline)


@torch.no_grad()
def _mean_squared_error(network: Network, examples, batch_size: int) -> float:
    """Mean squared offset error per coordinate (cm^2) over a resident example set."""
    network.eval()
    total = 0.0
    for start in range(0, len(examples), batch_size):
        x, y = examples.gather(torch.arange(start, min(start + batch_size, len(examples)), device=network.output_scale.device))
        total += float(torch.sum((network(x) - y) ** 2)) / y.shape[1]
    return total / len(examples)


@torch.no_grad()
def offset_errors(network: Network, examples, batch_size: int, unit: str) -> dict:
    """Errors of the predicted offsets (3-vectors) over every example, in cm, beside doing
    nothing (zero offsets); ``unit`` names the example count ("pairs", "frames")."""
    network.eval()
    squared = total = truth_squared = 0.0
    largest, vectors = 0.0, 0
    device = network.output_scale.device
    for chunk in examples.chunks():
        for start in range(0, len(chunk), batch_size):
            x, y = chunk.gather(torch.arange(start, min(start + batch_size, len(chunk)), device=device))
            dist = torch.linalg.norm((network(x) - y).reshape(-1, 3), dim=1).double()
            squared += float(torch.sum(dist**2))
            total += float(torch.sum(dist))
            largest = max(largest, float(torch.max(dist)))
            truth_squared += float(torch.sum(y.double() ** 2))
            vectors += len(dist)
    return {
        unit: len(examples),
        "rms_cm": float(np.sqrt(squared / vectors)),
        "mean_cm": total / vectors,
        "max_cm": largest,
        "zero_offset_rms_cm": float(np.sqrt(truth_squared / vectors)),
    }


def _prepare(take: TrainingSequence, face: FaceSetup, config: TrainConfig) -> Iterator[dict[str, np.ndarray]]:
    """A take's rows, PREPARE_FRAMES at a time: every frame, those away from its ends kept
    (on the take's own face setup if it has one).

    Columns: "skull" (B(t) or the skull motion input), "skin" (the samples' skull-space
    velocities xdot_i(t), a windowed column the store turns into X_i(t)), "targets", and
    with ``config.sample_positions`` "positions" (the samples' rest positions p_i, per row
    because a corpus of many faces has them per take).
    """
    face = take.face or face
    pts = check_points(take.points, f"take {take.name!r} points")
    if pts.shape[1] != face.point_count:
        raise ValueError(f"take {take.name!r} has {pts.shape[1]} points, the face setup {face.point_count}")
    f = len(pts)
    if f <= 2 * config.trim:
        raise ValueError(f"take {take.name!r} has {f} frames, too few to leave out {config.trim} at each end")
    t, q = check_transforms(take.translate, take.orient, f)
    samples, _ = replace_spikes(skull_space(pts[:, face.samples], t, q, take.space))  # what F reads (removal does the same)
    velocities = skin_velocities(samples, take.fps).astype(np.float32)
    if config.skull_motion is None:  # the paper's B(t): windows of the landmarks' velocities (facedyn.dynamics.features)
        landmark_velocities = skull_velocities(t, q, face.landmarks, take.fps).astype(np.float32)
        skull = span_windows(landmark_velocities, config.window, config.window).reshape(f, -1)
    else:
        skull = config.skull_motion.features(t, q, face.landmarks, take.fps)
    if config.target == "truth":
        if take.dynamics is None:
            raise ValueError(f"take {take.name!r} has no known dynamics to train on (target 'truth' needs a simulated corpus)")
        if np.shape(take.dynamics) != pts.shape:
            raise ValueError(f"take {take.name!r}: dynamics are {np.shape(take.dynamics)}, its points {pts.shape}")
        targets = take.dynamics  # sliced per chunk: a memory-mapped array stays on disk
    else:
        targets = dynamic_offsets(samples, space="skull", window=config.target_window).astype(np.float32)
    kept = np.zeros(f, bool)
    kept[config.trim: f - config.trim] = True
    for a in range(0, f, PREPARE_FRAMES):
        b = min(f, a + PREPARE_FRAMES)
        chunk_targets = np.asarray(targets[a:b])
        if config.target == "truth":
            chunk_targets = chunk_targets[:, face.samples]
        rows = {"skull": skull[a:b], "skin": velocities[a:b], "targets": chunk_targets, KEPT: kept[a:b]}
        if config.sample_positions:
            rows["positions"] = np.broadcast_to(sample_positions(face), (b - a, len(face.samples), 3))
        yield rows


def store_takes(takes: Iterable, prepare: Callable[[TrainingSequence], Iterator[dict[str, np.ndarray]]],
                scratch: Path | str | None = None, windows: dict[str, int] | None = None) -> tuple[TrainingStore, list[dict], float]:
    """(a store of every take's prepared rows, the takes' descriptions, their one frame rate).

    A prepared chunk may say which of its rows are examples under store.KEPT; ``windows``
    names the store's windowed columns (facedyn.dynamics.store.TrainingStore).

    ``takes`` may be any iterable of TrainingSequence objects or dicts, a generator included: each take
    is prepared and appended before the next is read, so a caller that reads takes lazily
    holds one take in memory at a time.
    """
    store: TrainingStore | None = None
    described: list[dict] = []
    fps = None
    try:
        for value in takes:
            take = TrainingSequence.coerce(value)
            rate = check_fps(take.fps)
            if fps is None:
                fps = rate
            elif abs(rate - fps) > 1e-6 * fps:
                raise ValueError(f"takes run at different frame rates ({described[0]['name']!r}: {fps}, {take.name!r}: {rate}); "
                                 "a model is trained for one rate")
            if any(d["name"] == take.name for d in described):
                raise ValueError(f"take names must be unique, got {take.name!r} twice")
            for arrays in prepare(take):
                kept = arrays.pop(KEPT, None)
                if store is None:
                    store = TrainingStore({name: a.shape[1:] for name, a in arrays.items()}, scratch, windows)
                store.append(take.name, arrays, kept)
            described.append({"name": take.name, "frames": int(len(take.points)), "space": take.space})
            del value, take, arrays  # before the next take is read
        if not described:
            raise ValueError("training needs at least one take")
    except BaseException:
        if store is not None:
            store.close()
        raise
    store.finish()
    return store, described, fps


def split_store(store: TrainingStore, described: list[dict], config: TrainConfig, items: int, make) -> tuple[StreamedExamples, StreamedExamples | None]:
    """(training examples, validation examples or None) of a store; marks the held-out takes in ``described``."""
    held = _split([d["name"] for d in described], config.validation)
    for d in described:
        d["validation"] = d["name"] in held
    train = StreamedExamples(store, store.rows_of(d["name"] for d in described if not d["validation"]), items, make, config.resident_bytes)
    val = StreamedExamples(store, store.rows_of(held), items, make, config.resident_bytes) if held else None
    return train, val


def _split(names: list[str], validation: Sequence[str] | None) -> set[str]:
    if validation is None:
        return {names[-1]} if len(names) >= 2 else set()
    held = set(validation)
    missing = held - set(names)
    if missing:
        raise ValueError(f"validation takes {sorted(missing)} are not among the takes {names}")
    if held >= set(names):
        raise ValueError("every take is held out for validation; nothing is left to train on")
    return held


def streamed_normalization(store: TrainingStore, names, inputs: Sequence[str], targets: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """(input mean, input std, target mean, target scale) over the named takes' rows.

    Input statistics are per feature, each input column's over its own rows (F's skull
    features per frame, its skin features and positions per (frame, sample) pair); targets
    get a mean per coordinate and one common scale, the RMS of their deviation from it.
    """
    stats = [store.moments(column, names) for column in inputs]
    out = store.moments(targets, names)
    mean = np.concatenate([m.mean for m in stats])
    std = np.sqrt(np.concatenate([m.variance for m in stats]))
    return mean, std, out.mean, float(np.sqrt(np.mean(out.variance)))


def train_removal(
    takes: Iterable,
    face: FaceSetup,
    config: TrainConfig | None = None,
    progress: ProgressCallback | None = None,
    *,
    scratch: Path | str | None = None,
    started: float | None = None,
) -> DynamicsModel:
    """Train network F on the takes (TrainingSequence objects or dicts, any iterable) for the given face setup.

    All takes must share one frame rate (the model's). Frames within ``config.trim`` of a
    take's ends are left out (their targets average over clamped windows). The skin
    features are stored as per-frame velocities and put together per batch (NumPy, no
    kernel needed). The examples go to a store in ``scratch`` (default: the system's temp folder), removed
    afterwards; at most ``config.resident_bytes`` of them are in memory at once. With
    ``config.time_limit_s``, training stops before an epoch that would end later than that
    many seconds from `started` (a time.monotonic() value; default: now), so a caller that
    read the takes first can count that time in.
    """
    config = config or TrainConfig()
    started = time.monotonic() if started is None else started
    deadline = None if config.time_limit_s is None else started + config.time_limit_s
    device = resolve_device(config.device)
    store, described, fps = store_takes(takes, lambda take: _prepare(take, face, config), scratch, {"skin": config.window})
    with store:
        samples = store.columns["skin"][0]
        train, val = split_store(store, described, config, samples,
                                 lambda a: PairSet(a["skull"], a["skin"], a[WINDOW_INDEX % "skin"], a["targets"], a.get("positions"), device))
        names = [d["name"] for d in described if not d["validation"]]
        inputs = ("skull", "skin") + (("positions",) if config.sample_positions else ())
        spec: NetworkSpec = removal_spec(store.columns["skull"][0], sum(store.feature_width(c) for c in inputs[1:]))
        normalization = streamed_normalization(store, names, inputs, "targets")
        network, curve = fit_new_network(spec, normalization, train, val, config, device, progress, deadline)
        errors = offset_errors(network, val, config.batch_size, "pairs") if val is not None else None
    network.cpu()
    info = {
        "training": {
            "takes": described,
            "train_pairs": len(train),
            "config": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(config).items()},
            "device": str(device),
        },
        "validation": errors,
        "loss_curve": curve,
    }
    windows = {"skull": config.window, "skin": config.window, "target": config.target_window}
    arrays = {SAMPLE_POSITIONS: sample_positions(face)} if config.sample_positions else {}
    return DynamicsModel(kind="removal", network=network, face=face, fps=fps, windows=windows, info=info, arrays=arrays,
                         skull_motion=config.skull_motion)
