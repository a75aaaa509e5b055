"""`remove` and `synthesize` as commands on the ICT rig: the whole command, and its read, compute and write.

A 1,000-frame stabilized take of the ICT-FaceKit skin (11,248 points; bench_remove_speed's
bobbing head with jiggling skin) is written to a scratch folder with a removal model F and a
synthesis model H with the rig's stretch arrays (both randomly initialised: speed does not
depend on the weights). Then, as a user runs them:

    usdfacedyn remove take.usda -o quasistatic.usdc --model actor.removal --attach take.usda
    usdfacedyn synthesize take.usda -o synthesized.usdc --model actor.synthesis --attach take.usda

One JSON object per command: ``command_seconds`` (wall, start-up included, the best of
--repeats runs, and every run) and ``frames_per_s`` from it (target, issue 40: >= 1,000);
``steps``: the same processor run in this process with its USD reading (TakeFrames),
layer writing (time samples and the file's export) and everything else ("compute")
timed apart; the layer's size; the machine's load average (it may be shared: the best
run is the figure, the load says how busy it was).

    python benchmarks/bench_command_io.py [--frames 1000] [--repeats 3] [--rig PATH] [--out FILE] [--note TEXT]

The propagation matrix of the models' face is kept on disk after its first solve
(facedyn.dynamics.propagator_cache): the first run on a machine solves it (1.5-3 s more),
later runs (and so the best of --repeats) read it.
"""
from __future__ import annotations

import contextlib
import io
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from bench_remove_speed import FPS, ICT_RIG, SAMPLES, take, write_still_take
from bench_synthesize_speed import synthesis_model
from harness import Recorder, parser


class StepClock:
    """Seconds spent in the wrapped functions, by step."""

    def __init__(self):
        self.seconds = {"read": 0.0, "write": 0.0}

    @contextlib.contextmanager
    def wrapping(self, targets: dict):
        """targets: step -> [(owner, attribute name)]; each wrapped while inside."""
        saved = []
        for step, places in targets.items():
            for owner, name in places:
                original = getattr(owner, name)
                saved.append((owner, name, original))
                setattr(owner, name, self._timed(step, original))
        try:
            yield self
        finally:
            for owner, name, original in reversed(saved):
                setattr(owner, name, original)

    def _timed(self, step, fn):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                self.seconds[step] += time.perf_counter() - start
        return timed


def build_take(folder: Path, frames: int, rig_path: Path):
    """The stabilized take (take.usda), F (actor.removal) and H (actor.synthesis)."""
    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.modelfile import DynamicsModel, save_model
    from facedyn.dynamics.network import Network, removal_spec
    from facedyn.dynamics.stretch import UVNeighbourhoods
    from facedyn.usd.blendshape_rig import read_blendshape_rig

    rig = read_blendshape_rig(rig_path)
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, sample_count=SAMPLES)
    skull_points, translate, orient = take(rig.neutral.astype(np.float64), frames)
    root = write_still_take(folder, rig, skull_points, translate, orient, "take.usda")
    torch.manual_seed(0)
    removal = DynamicsModel("removal", Network(removal_spec()), face, FPS, {"skull": 10, "skin": 10, "target": 10})
    save_model(removal, folder / "actor.removal")
    save_model(synthesis_model(face, UVNeighbourhoods.build(rig.topology, rig.uvs, rig.neutral, face.samples)), folder / "actor.synthesis")
    return root, rig.point_count


def command(name: str, folder: Path) -> list[str]:
    model = folder / ("actor.removal" if name == "remove" else "actor.synthesis")
    output = folder / ("quasistatic.usdc" if name == "remove" else "synthesized.usdc")
    return [name, str(folder / "take.usda"), "-o", str(output), "--model", str(model), "--attach", str(folder / "take.usda")]


def run_command(argv: list[str]) -> tuple[float, float]:
    """Wall and CPU (user + system: what a busy machine inflates least) seconds of the command."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    started = time.perf_counter()
    done = subprocess.run([sys.executable, "-m", "facedyn.cli", *argv, "-q"], capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"usdfacedyn {' '.join(argv)} failed: {done.stderr.strip()}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.perf_counter() - started, after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime


def steps_in_process(argv: list[str]) -> dict:
    """The command's processor run here (no start-up), its read and write timed apart from the rest."""
    from facedyn.cli import main
    from facedyn.usd import frames, layers

    clock = StepClock()
    targets = {"read": [(frames.TakeFrames, n) for n in ("__init__", "read", "read_frames", "skull")],
               "write": [(layers, "_author_time_samples"), (layers, "export_atomically")]}
    with clock.wrapping(targets), contextlib.redirect_stdout(io.StringIO()):  # the JSON lines stay this benchmark's
        started = time.perf_counter()
        if main([*argv, "-q"]) != 0:
            raise SystemExit(f"usdfacedyn {' '.join(argv)} failed")
        total = time.perf_counter() - started
    return {"total": round(total, 3), "read": round(clock.seconds["read"], 3), "write": round(clock.seconds["write"], 3),
            "compute": round(total - clock.seconds["read"] - clock.seconds["write"], 3)}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=1000)
    arguments.add_argument("--repeats", type=int, default=3)
    arguments.add_argument("--rig", type=Path, default=ICT_RIG)
    args = arguments.parse_args()
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="facedyn-bench-io-") as scratch, Recorder("bench_command_io", args) as record:
        folder = Path(scratch)
        root, points = build_take(folder, args.frames, args.rig)
        for name in ("remove", "synthesize"):
            argv = command(name, folder)
            runs = [run_command(argv) for _ in range(args.repeats)]
            steps = min((steps_in_process(argv) for _ in range(args.repeats)), key=lambda s: s["total"])
            output = Path(argv[3])
            best = min(r[0] for r in runs)
            record({
                "case": f"{name} command", "mesh": args.rig.stem, "points": points, "frames": args.frames,
                "usdfacedyn_command": "usdfacedyn " + " ".join(a.replace(scratch, "$TMP") for a in argv),
                "command_seconds": round(best, 3), "command_seconds_all_runs": [round(r[0], 3) for r in runs],
                "command_cpu_seconds": round(min(r[1] for r in runs), 3),
                "frames_per_s": round(args.frames / best, 1), "target_frames_per_s": 1000,
                "steps_in_process_s": steps, "layer_mb": round(output.stat().st_size / 2**20, 1),
                "cpu_count": os.cpu_count(),
                "load_average": {"before": [round(x, 2) for x in load_before], "after": [round(x, 2) for x in os.getloadavg()]},
            })


if __name__ == "__main__":
    main()
