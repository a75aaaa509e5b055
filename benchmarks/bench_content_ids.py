"""What identifying inputs by content costs: hashing a long take's layers, beside writing them.

Every step hashes the layers it reads (facedyn.usd.runs.content_id, a streamed sha256 of the
bytes, clips included) and `usdfacedyn layers`/`validate` hash every layer of the stack to
decide what is stale. This writes a take of --frames frames of a 4,096-point mesh (the size
of the built-in face) as import, stabilize and remove would (capture; stabilized points
and skull; quasistatic points and offsets), each layer through `write_layer`, then times,
with the in-process digest cache emptied: each layer's content id, and a whole
`stack_status` of the root (what `layers` does), and the machine's sha256 speed over bytes
in memory (the ceiling). The files were just written, so they are mostly read from the
page cache: the figures are the hash's cost, not a cold disk's.

    python benchmarks/bench_content_ids.py [--frames 5000 10000] [--workdir DIR] [--keep] [--out FILE] [--note TEXT]

Prints one JSON object per frame count. Past 5,000 frames the layers are value clips.
"""
from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from facedyn.performance import Topology
from facedyn.usd import runs, schema
from facedyn.usd.layers import LayerContent, write_layer
from facedyn.usd.rootedit import attach
from facedyn.usd.stackstatus import stack_status
from facedyn.usd.take import read_inputs, stage_below
from facedyn.usd.timing import Timing

from harness import Recorder, parser

SIDE = 64  # 64 x 64 = 4,096 points
CHUNK = 500  # frames per chunk written


def grid() -> tuple[np.ndarray, Topology]:
    ys, xs = np.mgrid[0:SIDE, 0:SIDE]
    points = np.stack([xs.ravel(), ys.ravel(), np.zeros(SIDE * SIDE)], axis=1).astype(np.float32)
    quads = [[r * SIDE + c, r * SIDE + c + 1, r * SIDE + c + SIDE + 1, r * SIDE + c + SIDE]
             for r in range(SIDE - 1) for c in range(SIDE - 1)]
    return points, Topology(np.full(len(quads), 4, np.int32), np.asarray(quads, np.int32).ravel())


def chunks(frames: np.ndarray, rest: np.ndarray, seed: int, role: str, skull: bool = False, offsets: bool = False):
    rng = np.random.default_rng(seed)
    for lo in range(0, len(frames), CHUNK):
        f = frames[lo:lo + CHUNK]
        points = rest[None] + rng.normal(0, 0.1, (len(f), len(rest), 3)).astype(np.float32)
        yield LayerContent(
            frames=f, points=points, face=schema.FaceAttributes(role=role),
            skull_translate=np.zeros((len(f), 3)) if skull else None,
            skull_orient=np.tile([1.0, 0, 0, 0], (len(f), 1)) if skull else None,
            offsets=rng.normal(0, 0.01, points.shape).astype(np.float32) if offsets else None,
        )


def build(folder: Path, count: int) -> tuple[Path, dict[str, float]]:
    rest, topology = grid()
    frames = np.arange(1001, 1001 + count, dtype=np.float64)
    timing = Timing(120.0, 120.0, frames[0], frames[-1])
    span = (frames[0], frames[-1])
    root = folder / "take.usda"
    written = {}
    steps = [("capture.usdc", "captured", "import", dict(), True),
             ("stabilized.usdc", "stabilized", "stabilize", dict(skull=True), False),
             ("quasistatic.usdc", "quasistatic", "remove", dict(offsets=True), False)]
    for seed, (name, role, processor, extra, define) in enumerate(steps):
        inputs = [] if define else list(read_inputs(stage_below(root, role)))
        head = LayerContent(frames=frames, face=schema.FaceAttributes(role=role), topology=topology if define else None,
                            skull=schema.SkullAttributes(solver="bench") if define or extra.get("skull") else None)
        started = time.perf_counter()
        provenance = schema.Provenance(processor, "bench", {}, span, inputs, role=role)
        path = write_layer(folder / name, head, timing, provenance, define=define, chunks=chunks(frames, rest, seed, role, **extra))
        written[name] = time.perf_counter() - started
        attach(root, path, role, create_with=timing if define else None)
    return root, written


def layer_bytes(path: Path) -> int:
    clips = [p for folder in path.parent.glob(f"{path.stem}.*.clips") for p in folder.iterdir()]
    return path.stat().st_size + sum(p.stat().st_size for p in clips)


def measure(count: int, workdir: Path, keep: bool) -> dict:
    folder = Path(tempfile.mkdtemp(prefix=f"content_ids_{count}_", dir=workdir))
    try:
        root, written = build(folder, count)
        layers = {}
        for name in ("capture.usdc", "stabilized.usdc", "quasistatic.usdc"):
            runs._DIGESTS.clear()
            started = time.perf_counter()
            runs.content_id(folder / name)
            seconds = time.perf_counter() - started
            size = layer_bytes(folder / name)
            layers[name] = {"bytes": size, "hash_s": round(seconds, 3), "hash_MB_per_s": round(size / 2**20 / seconds, 1),
                            "write_s": round(written[name], 2)}
        runs._DIGESTS.clear()
        started = time.perf_counter()
        states = [s.state for s in stack_status(root)]
        cold = time.perf_counter() - started
        started = time.perf_counter()
        stack_status(root)
        warm = time.perf_counter() - started
        return {"case": "content ids", "frames": count, "points": SIDE * SIDE, "clips": count > 5000, "layers": layers,
                "sha256_in_memory_MB_per_s": round(sha256_speed(), 1),
                "stack_status_s": round(cold, 3), "stack_status_cached_s": round(warm, 3), "states": states,
                "hash_share_of_writing": round(sum(v["hash_s"] for v in layers.values()) / sum(written.values()), 3)}
    finally:
        if not keep:
            shutil.rmtree(folder, ignore_errors=True)


def sha256_speed() -> float:
    """This machine's sha256 over bytes already in memory, now: the ceiling of hashing (a loaded machine is slower)."""
    data = np.random.default_rng(0).bytes(1 << 27)
    started = time.perf_counter()
    hashlib.sha256(data).digest()
    return 128 / (time.perf_counter() - started)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, nargs="+", default=[5000])
    arguments.add_argument("--workdir", type=Path, default=Path(tempfile.gettempdir()))
    arguments.add_argument("--keep", action="store_true")
    args = arguments.parse_args()
    with Recorder("bench_content_ids", args) as record:
        for count in args.frames:
            record(measure(count, args.workdir, args.keep))


if __name__ == "__main__":
    main()
