"""Take I/O speed: write and read 1,000 frames of an 11,248-point mesh (the ICT rig's size).

Prints one JSON object per case. Target (issue 2): each under 2 s on 2 cores.

    python benchmarks/bench_take_io.py [--frames 1000] [--points 11248] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from facedyn.geometry import quaternion
from facedyn.performance import Topology
from facedyn.usd import schema
from facedyn.usd.layers import LayerContent, write_layer, write_take_root
from facedyn.usd.take import read_take
from facedyn.usd.timing import Timing

from harness import Recorder, parser


def make_layers(frames: int, points: int):
    rng = np.random.default_rng(0)
    base = rng.normal(scale=10.0, size=(points, 3)).astype(np.float32)
    motion = rng.normal(scale=0.05, size=(frames, 1, 3)).astype(np.float32)
    world = base[None] + motion
    tris = rng.integers(0, points, size=(2 * points, 3)).astype(np.int32)
    topology = Topology(np.full(len(tris), 3, np.int32), tris.ravel())
    time_codes = np.arange(1001, 1001 + frames, dtype=np.float64)
    capture = LayerContent(frames=time_codes, points=world, topology=topology, skull=schema.SkullAttributes())
    orient = quaternion.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.linspace(0, 0.3, frames))
    stabilized = LayerContent(
        frames=time_codes, points=world, skull_translate=np.zeros((frames, 3)), skull_orient=orient,
        solve_error=np.zeros(frames), face=schema.FaceAttributes(role="stabilized"),
        skull=schema.SkullAttributes(solver="mode-pursuit"),
    )
    quasistatic = LayerContent(frames=time_codes, points=world, offsets=world * 0.01, face=schema.FaceAttributes(role="quasistatic"))
    return time_codes, {"capture": (capture, True), "stabilized": (stabilized, False), "quasistatic": (quasistatic, False)}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=1000)
    arguments.add_argument("--points", type=int, default=11248)
    args = arguments.parse_args()
    time_codes, contents = make_layers(args.frames, args.points)
    timing = Timing(120.0, 120.0, time_codes[0], time_codes[-1])
    with tempfile.TemporaryDirectory() as tmp, Recorder("bench_take_io", args) as record:
        folder = Path(tmp)
        written = []
        for name, (content, define) in contents.items():
            prov = schema.Provenance(name, "bench", {}, (time_codes[0], time_codes[-1]), [])
            started = time.perf_counter()
            path = write_layer(folder / f"{name}.usdc", content, timing, prov, define=define)
            seconds = time.perf_counter() - started
            written.append(path)
            record({"case": f"write {name} layer", "frames": args.frames, "points": args.points,
                    "seconds": round(seconds, 3), "target_seconds": 2.0, "mb": round(path.stat().st_size / 1e6, 1)})
        root = write_take_root(folder / "take.usda", written[::-1], timing)
        for label, path in (("capture layer alone", written[0]), ("composed take (3 layers)", root)):
            started = time.perf_counter()
            perf, _ = read_take(path)
            float(perf.points.sum())  # touch every value
            seconds = time.perf_counter() - started
            record({"case": f"read {label}", "frames": perf.frame_count, "points": perf.point_count,
                    "seconds": round(seconds, 3), "target_seconds": 2.0})


if __name__ == "__main__":
    main()
