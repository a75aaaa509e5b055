"""F's training on a corpus: seconds per epoch, peak memory and the validation loss per epoch.

Trains network F with `calibrate`'s flags (true skull and targets, skull accelerations,
sample positions, batches of 2,000, half the pairs an epoch) on a simulated corpus
(`usdfacedyn simulate`), in a fresh process so its peak resident memory (VmHWM) is its own:

    python benchmarks/bench_train_epoch.py CORPUS --epochs 3 --out benchmarks/results/train_epoch.json

The first epoch's time includes reading the corpus and preparing the store; the later
epochs are the training itself. The validation loss per epoch is what a change to the
training must keep (issue 40: "the same validation loss per epoch as today").
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from harness import Recorder, parser


def peak_rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def child(corpus: list[Path], epochs: int, subsample: float, batch_size: int, resident_mib: int, threads: int) -> dict:
    """Train F once on the corpus; the figures as a dict."""
    from dataclasses import replace

    import torch

    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.skull_motion import NAMED
    from facedyn.dynamics.training import TrainConfig, train_removal
    from facedyn.dynamics.training_sequence import TrainingSequence
    from facedyn.usd.corpus_files import read_truth
    from facedyn.usd.training_data import read_training_take, take_roots

    torch.set_num_threads(threads)
    roots = take_roots(corpus)
    first, _ = read_training_take(roots[0], "truth")
    face = FaceSetup.from_performance(first)
    del first

    def takes():
        for root in roots:
            perf, _ = read_training_take(root, "truth")
            yield replace(TrainingSequence.from_performance(perf, root.name), dynamics=read_truth(root).offsets)

    ends: list[float] = []
    losses: list[float | None] = []
    config = TrainConfig(epochs=epochs, subsample=subsample, batch_size=batch_size, target="truth", skull_motion=NAMED["acceleration"],
                         sample_positions=True, resident_bytes=resident_mib << 20, device="cpu")
    started = time.perf_counter()
    model = train_removal(takes(), face, config, progress=lambda epoch, train, val: (ends.append(time.perf_counter()), losses.append(val)))
    epoch_seconds = [b - a for a, b in zip(ends[:-1], ends[1:])]
    return {"takes": len(roots), "points": face.point_count, "samples": int(len(face.samples)),
            "train_pairs": model.info["training"]["train_pairs"], "epochs": epochs, "subsample": subsample, "batch_size": batch_size,
            "torch_threads": threads, "resident_mib": resident_mib,
            "first_epoch_with_preparation_s": round(ends[0] - started, 1),
            "seconds_per_epoch": round(sum(epoch_seconds) / len(epoch_seconds), 1) if epoch_seconds else None,
            "validation_loss_per_epoch_cm2": [None if v is None else round(v, 8) for v in losses],
            "validation_rms_cm": round(model.info["validation"]["rms_cm"], 5), "peak_rss_mib": round(peak_rss_mib(), 1)}


def main() -> None:
    args = parser(__doc__)
    args.add_argument("corpus", type=Path, nargs="+", help="a corpus folder, or take folders")
    args.add_argument("--epochs", type=int, default=3)
    args.add_argument("--subsample", type=float, default=0.5)
    args.add_argument("--batch-size", type=int, default=2000)
    args.add_argument("--resident-mib", type=int, default=1024, help="examples in memory at once (TrainConfig.resident_bytes)")
    args.add_argument("--threads", type=int, default=2, help="torch threads")
    args.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = args.parse_args()
    flags = (args.epochs, args.subsample, args.batch_size, args.resident_mib, args.threads)
    if args.child:
        print(json.dumps(child(args.corpus, *flags)))
        return
    with Recorder("bench_train_epoch", args) as record:
        out = subprocess.run([sys.executable, __file__, *map(str, args.corpus), "--child", "--epochs", str(args.epochs), "--subsample", str(args.subsample),
                              "--batch-size", str(args.batch_size), "--resident-mib", str(args.resident_mib), "--threads", str(args.threads)],
                             check=True, stdout=subprocess.PIPE, text=True).stdout
        record({"case": "train_F_epoch", "corpus": " ".join(map(str, args.corpus)), **json.loads(out.strip().splitlines()[-1]),
                "obtained": {"skull": "true", "targets": "true dynamics", "corpus": "usdfacedyn simulate (facedyn.sim.tissue)"}})


if __name__ == "__main__":
    main()
