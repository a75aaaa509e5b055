"""Training examples on disk: computed once per take, streamed back in shuffled chunks.

A production corpus (hundreds of takes of thousands of frames) does not fit in memory as
network inputs: F's skin features alone are 63 floats per skin sample per frame. The
trainers (facedyn.dynamics.training, .synthesis) therefore prepare one take at a time and
append its per-frame arrays ("columns", e.g. skull features, skin features, targets) to
flat float32 files in a scratch folder (`TrainingStore`), keeping per-column running
moments for the normalization. Training then reads the examples back in chunks of at most
``resident_bytes`` (`StreamedExamples`): each epoch permutes blocks of consecutive frames,
loads a chunk of blocks with plain file reads (no memory map, whose touched pages would
count towards the process's memory), and the trainer shuffles within the chunk. A corpus
that fits in one chunk is loaded once and shuffled whole, exactly as an in-memory trainer.

A *windowed* column holds what every row reads over a window of frames (F's skin features
X_i(t) are the velocities of frames t-w..t+w): the store keeps one value per frame and
hands each row the index of its window's frames (`read_windows`), so the windows are put
together batch by batch and never stored, 2w+1 = 21 times less than the features. Its
rows are every frame of a take; `kept` marks those that are examples (the others are
window context, e.g. the trimmed ends of a take).
"""
from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
import torch

KEPT = "kept"  # the key under which a prepared chunk of rows may say which of them are examples (the rest: window context)
WINDOW_INDEX = "%s_window"  # the loaded array of a windowed column's per-row window indices
BLOCK_FRAMES = 32  # frames read together; the unit of the between-chunk shuffle
_MOMENT_ROWS = 65536  # rows per float64 statistics step (bounds its temporary copy)


@dataclass
class Moments:
    """Count, mean and sum of squared deviations per feature (Chan et al.'s parallel update)."""

    count: int
    mean: np.ndarray
    m2: np.ndarray

    @classmethod
    def empty(cls, width: int) -> "Moments":
        return cls(0, np.zeros(width), np.zeros(width))

    @classmethod
    def of(cls, rows: np.ndarray) -> "Moments":
        rows = np.asarray(rows, dtype=np.float64)
        mean = rows.mean(axis=0)
        return cls(len(rows), mean, ((rows - mean) ** 2).sum(axis=0))

    def merge(self, other: "Moments") -> "Moments":
        n = self.count + other.count
        if n == 0:
            return self
        delta = other.mean - self.mean
        mean = self.mean + delta * (other.count / n)
        m2 = self.m2 + other.m2 + delta**2 * (self.count * other.count / n)
        return Moments(n, mean, m2)

    @property
    def variance(self) -> np.ndarray:
        """Population variance per feature (as numpy's std with ddof=0)."""
        return self.m2 / max(self.count, 1)


def moments_of(values: np.ndarray) -> Moments:
    """Moments over the last axis of (..., D) values, every leading index one row."""
    rows = values.reshape(-1, values.shape[-1])
    total = Moments.empty(rows.shape[1])
    for start in range(0, len(rows), _MOMENT_ROWS):
        total = total.merge(Moments.of(rows[start: start + _MOMENT_ROWS]))
    return total


@dataclass
class StoredTake:
    """A take's rows [start, stop) in the store and its moments per column."""

    name: str
    start: int
    stop: int
    moments: dict[str, Moments] = field(default_factory=dict)
    kept: list[np.ndarray] = field(default_factory=list)  # per appended run of rows: which are examples

    def kept_rows(self) -> np.ndarray:
        return self.start + np.flatnonzero(np.concatenate(self.kept)) if self.kept else np.zeros(0, np.int64)


class TrainingStore:
    """Per-frame float32 arrays of many takes, appended take by take to files in a folder.

    columns: name -> shape of one frame's value (e.g. ``{"skull": (315,), "skin": (344, 3)}``);
    windows: windowed column -> its half-window w (the row reads frames t-w..t+w of its take,
    zero beyond the take's ends). The folder is created inside ``scratch`` (default: the
    system's temp folder) and removed by `close` (or leaving a ``with`` block).
    """

    def __init__(self, columns: dict[str, tuple[int, ...]], scratch: Path | str | None = None, windows: dict[str, int] | None = None):
        self.columns = {name: tuple(int(s) for s in shape) for name, shape in columns.items()}
        self.windows = {name: int(w) for name, w in (windows or {}).items()}
        if set(self.windows) - set(self.columns) or any(w < 0 for w in self.windows.values()):
            raise ValueError(f"windows {self.windows} must name store columns {sorted(self.columns)} with half-windows >= 0")
        self.folder = Path(tempfile.mkdtemp(prefix="facedyn-store-", dir=scratch))
        self.takes: list[StoredTake] = []
        self.rows = 0
        self._files = {name: open(self._path(name), "wb") for name in self.columns}

    def __enter__(self) -> "TrainingStore":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Close and delete the store's files."""
        for f in self._files.values():
            f.close()
        shutil.rmtree(self.folder, ignore_errors=True)

    def _path(self, column: str) -> Path:
        return self.folder / f"{column}.f32"

    def row_bytes(self, columns: Sequence[str] | None = None) -> int:
        """Bytes a loaded row takes: its values, and a windowed column's index of its window."""
        return sum(4 * int(np.prod(self.columns[c])) + 8 * (2 * self.windows[c] + 1 if c in self.windows else 0)
                   for c in (columns or self.columns))

    def append(self, take: str, arrays: dict[str, np.ndarray], kept: np.ndarray | None = None) -> None:
        """Append rows of `take` (every column, the same number of frames); a take's rows
        may come in several calls in a row (a long take prepared in chunks of frames).

        kept: which rows are examples (default: all); only they count in the moments and
        in `rows_of`. A store with windowed columns needs every frame of a take, in order.
        """
        if set(arrays) != set(self.columns):
            raise ValueError(f"store columns are {sorted(self.columns)}, got {sorted(arrays)}")
        counts = {len(a) for a in arrays.values()}
        if len(counts) != 1:
            raise ValueError(f"take {take!r}: columns of different frame counts {sorted(counts)}")
        count = counts.pop()
        kept = np.ones(count, bool) if kept is None else np.asarray(kept, bool)
        if kept.shape != (count,):
            raise ValueError(f"take {take!r}: kept must say for each of the {count} rows whether it is an example, got {kept.shape}")
        if not self.takes or self.takes[-1].name != take:
            if any(t.name == take for t in self.takes):
                raise ValueError(f"take names must be unique, got {take!r} twice")
            self._finish_take()
            self.takes.append(StoredTake(take, self.rows, self.rows))
        entry = self.takes[-1]
        for name, values in arrays.items():
            values = np.ascontiguousarray(values, dtype=np.float32)
            if values.shape[1:] != self.columns[name]:
                raise ValueError(f"take {take!r}: column {name!r} rows are {values.shape[1:]}, the store's {self.columns[name]}")
            self._files[name].write(values.tobytes())
            if name not in self.windows:
                added = moments_of(values[kept])
                entry.moments[name] = entry.moments[name].merge(added) if name in entry.moments else added
        entry.kept.append(kept)
        entry.stop += count
        self.rows += count

    def _finish_take(self) -> None:
        """The last take's windowed moments, once all its frames are in: each window entry's
        moments over the kept rows, read back from the files."""
        if not self.windows or not self.takes:
            return
        entry = self.takes[-1]
        kept = np.flatnonzero(np.concatenate(entry.kept)) if entry.kept else np.zeros(0, np.int64)
        frames = np.arange(entry.start, entry.stop)
        for name, w in self.windows.items():
            self._files[name].flush()
            series = self.read(name, frames)
            padded = np.zeros((len(series) + 2 * w, *series.shape[1:]), np.float32)
            padded[w: w + len(series)] = series
            per_entry = [moments_of(padded[kept + j]) for j in range(2 * w + 1)]  # entry j is frame t - w + j
            entry.moments[name] = Moments(per_entry[0].count, np.concatenate([m.mean for m in per_entry]),
                                          np.concatenate([m.m2 for m in per_entry]))

    def finish(self) -> None:
        """Flush the files so that reads see every appended row."""
        for f in self._files.values():
            f.flush()
        self._finish_take()

    def rows_of(self, names) -> np.ndarray:
        """The example rows (kept) of the named takes, in store order."""
        names = set(names)
        ranges = [t.kept_rows() for t in self.takes if t.name in names]
        return np.concatenate(ranges) if ranges else np.zeros(0, np.int64)

    def feature_width(self, column: str) -> int:
        """Features per item a row of the column gives: a windowed column's whole window."""
        return self.columns[column][-1] * (2 * self.windows[column] + 1 if column in self.windows else 1)

    def moments(self, column: str, names) -> Moments:
        """The column's moments over the named takes' example rows (a windowed column: over their windows)."""
        names = set(names)
        total = Moments.empty(self.feature_width(column))
        for t in self.takes:
            if t.name in names and column in t.moments:
                total = total.merge(t.moments[column])
        return total

    def read(self, column: str, rows: np.ndarray) -> np.ndarray:
        """The column's values at sorted store rows, read run by run from its file."""
        shape = self.columns[column]
        width = int(np.prod(shape))
        out = np.empty((len(rows), width), np.float32)
        if len(rows) == 0:
            return out.reshape((0, *shape))
        breaks = np.flatnonzero(np.diff(rows) != 1) + 1
        starts = np.concatenate([[0], breaks])
        stops = np.concatenate([breaks, [len(rows)]])
        with open(self._path(column), "rb") as f:
            for a, b in zip(starts, stops):
                f.seek(int(rows[a]) * width * 4)
                out[a:b] = np.fromfile(f, np.float32, (b - a) * width).reshape(b - a, width)
        return out.reshape((len(rows), *shape))

    def read_windows(self, column: str, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(values (U + 1, *shape), index (len(rows), 2w + 1)) of a windowed column at sorted rows.

        values[index[k, j]] is frame t - w + j of row k's take (t: row k's frame); frames
        beyond the take's ends point at values[-1], zero.
        """
        w = self.windows[column]
        starts = np.array([t.start for t in self.takes], np.int64)
        stops = np.array([t.stop for t in self.takes], np.int64)
        take = np.searchsorted(starts, rows, side="right") - 1
        wanted = rows[:, None] + np.arange(-w, w + 1)[None, :]
        inside = (wanted >= starts[take][:, None]) & (wanted < stops[take][:, None])
        needed = np.unique(wanted[inside])
        values = np.zeros((len(needed) + 1, *self.columns[column]), np.float32)
        values[:-1] = self.read(column, needed)
        index = np.where(inside, np.searchsorted(needed, wanted), len(needed))
        return values, index


# A resident example set from the arrays of some store rows (one key per column).
MakeResident = Callable[[dict[str, np.ndarray]], object]


class StreamedExamples:
    """The examples of some store rows, handed out as resident example sets of bounded size.

    ``items`` examples per row (F: every skin sample of a frame; H: 1). ``make`` builds a
    resident example set (with ``len`` and ``gather``) from the arrays of a chunk's rows.
    """

    def __init__(self, store: TrainingStore, rows: np.ndarray, items: int, make: MakeResident, resident_bytes: int):
        self.store = store
        self.rows = np.asarray(rows, dtype=np.int64)
        self.items = int(items)
        self.make = make
        self.chunk_rows = max(BLOCK_FRAMES, int(resident_bytes) // max(store.row_bytes(), 1) // BLOCK_FRAMES * BLOCK_FRAMES)
        self._whole = None

    def __len__(self) -> int:
        return len(self.rows) * self.items

    @property
    def resident(self) -> bool:
        """Whether every example fits in one chunk (loaded once, kept)."""
        return len(self.rows) <= self.chunk_rows

    def load(self, rows: np.ndarray):
        """A resident example set of these store rows (sorted); a windowed column comes as
        its values and, under WINDOW_INDEX % column, each row's window into them."""
        arrays = {}
        for c in self.store.columns:
            if c in self.store.windows:
                arrays[c], arrays[WINDOW_INDEX % c] = self.store.read_windows(c, rows)
            else:
                arrays[c] = self.store.read(c, rows)
        return self.make(arrays)

    def chunks(self, generator: torch.Generator | None = None) -> Iterator:
        """Resident example sets that together hold every example once.

        With a generator, blocks of BLOCK_FRAMES consecutive rows go to the chunks in a
        random order (drawn from it); without, in store order. A set that fits in one chunk
        is yielded whole and draws nothing, so it trains exactly like an in-memory set.
        """
        if self.resident:
            if self._whole is None:
                self._whole = self.load(self.rows)
            yield self._whole
            return
        blocks = np.arange(0, len(self.rows), BLOCK_FRAMES)
        if generator is not None:
            blocks = blocks[torch.randperm(len(blocks), generator=generator).numpy()]
        per_chunk = self.chunk_rows // BLOCK_FRAMES
        for first in range(0, len(blocks), per_chunk):
            picked = np.sort(blocks[first: first + per_chunk])
            positions = np.concatenate([np.arange(b, min(b + BLOCK_FRAMES, len(self.rows))) for b in picked])
            yield self.load(self.rows[positions])

    def subset(self, max_examples: int, generator: torch.Generator):
        """A resident set of whole rows drawn at random, at most ``max_examples`` examples
        and one chunk (all of them when they fit): what a per-epoch validation loss reads."""
        count = min(len(self.rows), max(1, int(max_examples) // self.items), self.chunk_rows)
        if count == len(self.rows):
            return next(self.chunks())
        picked = np.sort(torch.randperm(len(self.rows), generator=generator)[:count].numpy())
        return self.load(self.rows[picked])
