"""Peak memory of training F and H on corpora of N and 4N takes: flat, whatever the corpus size.

Simulates a corpus of --takes * 4 walking / hopping / platform takes of the built-in face
(--seconds each, 120 fps; `usdfacedyn simulate`'s USD layout), then trains in a fresh
subprocess per case, reading the takes lazily from USD one at a time (a generator of
TrainingSequence objects, true skull and true dynamics; H reads the true quasistatic shapes through a
lazy mapping) into the on-disk store, with at most --resident-mib of examples in memory.
Each case prints one JSON object with the process's peak resident memory (VmHWM):

    python benchmarks/bench_train_memory.py --takes 4 [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Mapping
from pathlib import Path

from harness import Recorder, parser
from spill import scratch_folder

MOTIONS = ("walk", "hop", "platform:7", "platform:9")


def peak_rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def build(folder: Path, count: int, seconds: float) -> None:
    from facedyn.sim.corpus import TakeSpec
    from facedyn.sim.default_face import default_face
    from facedyn.processors.corpus_writer import build_corpus

    specs = [TakeSpec(f"take{i:03d}", MOTIONS[i % len(MOTIONS)], ("smile", "jaw_open", None)[i % 3], duration_s=seconds, seed=i)
             for i in range(count)]
    build_corpus(folder, default_face(), specs, jobs=2)


class LazyTruth(Mapping):
    """{take name: its true quasistatic points}, read from the corpus when asked for."""

    def __init__(self, folders: dict[str, Path]):
        self.folders = folders

    def __getitem__(self, name):
        from facedyn.usd.corpus_files import read_truth

        return read_truth(self.folders[name]).points

    def __iter__(self):
        return iter(self.folders)

    def __len__(self):
        return len(self.folders)


def child(corpus: Path, count: int, network: str, resident_mib: int, epochs: int) -> None:
    """Train one network on the first `count` takes; print its case (the parent records it) with the peak memory."""
    from dataclasses import replace

    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.skull_motion import SkullMotionInput
    from facedyn.dynamics.synthesis_training import synthesis_config, train_synthesis
    from facedyn.dynamics.training import TrainConfig, train_removal
    from facedyn.dynamics.training_sequence import TrainingSequence
    from facedyn.usd.corpus_files import read_truth
    from facedyn.usd.training_data import read_training_take, take_roots

    roots = take_roots([corpus])[:count]
    first, _ = read_training_take(roots[0], "truth")
    face = FaceSetup.from_performance(first)
    uvs, frames = first.uvs, len(first.points)
    del first

    def takes():
        for root in roots:
            perf, _ = read_training_take(root, "truth")
            take = TrainingSequence.from_performance(perf, root.name)
            yield replace(take, dynamics=read_truth(root).offsets) if network == "F" else take

    started = time.perf_counter()
    budget = resident_mib << 20
    if network == "F":
        config = TrainConfig(epochs=epochs, target="truth", skull_motion=SkullMotionInput(), resident_bytes=budget, device="cpu")
        model = train_removal(takes(), face, config)
        examples = model.info["training"]["train_pairs"]
    else:
        config = synthesis_config(epochs=epochs, resident_bytes=budget, device="cpu")
        model = train_synthesis(takes(), face, uvs, LazyTruth({root.name: root for root in roots}), config)
        examples = model.info["training"]["train_frames"]
    print(json.dumps({"case": "train_memory", "network": network, "takes": count, "frames": count * frames, "points": face.point_count,
                      "samples": int(len(face.samples)), "train_examples": examples, "epochs": epochs, "resident_mib": resident_mib,
                      "seconds": round(time.perf_counter() - started, 1), "peak_rss_mib": round(peak_rss_mib(), 1),
                      "validation_rms_cm": round(model.info["validation"]["rms_cm"], 4)}), flush=True)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--takes", type=int, default=4, help="the small corpus; the large one has 4 times as many")
    arguments.add_argument("--seconds", type=float, default=2.0)
    arguments.add_argument("--epochs", type=int, default=2)
    arguments.add_argument("--resident-mib", type=int, default=128, help="examples in memory at once (TrainConfig.resident_bytes)")
    arguments.add_argument("--networks", nargs="+", default=["F", "H"], choices=("F", "H"))
    arguments.add_argument("--child", nargs=3, metavar=("CORPUS", "TAKES", "NETWORK"), help=argparse.SUPPRESS)
    args = arguments.parse_args()
    if args.child:
        child(Path(args.child[0]), int(args.child[1]), args.child[2], args.resident_mib, args.epochs)
        return
    corpus = scratch_folder() / "corpus"
    with Recorder("bench_train_memory", args) as record:
        build(corpus, 4 * args.takes, args.seconds)
        for network in args.networks:
            for count in (args.takes, 4 * args.takes):
                done = subprocess.run([sys.executable, __file__, "--child", str(corpus), str(count), network, "--resident-mib", str(args.resident_mib),
                                       "--epochs", str(args.epochs)], check=True, stdout=subprocess.PIPE, text=True)
                record(json.loads(done.stdout.splitlines()[-1]))


if __name__ == "__main__":
    main()
