"""Does the recommended corpus, Live Link performances included, complete on a rig? (issue 37)

Runs the README's corpus command as a user runs it, as its own process:

    usdfacedyn simulate --rig RIG --scale standard --randomize-tissue take --extra-motions true \
        --impacts true --noise 0.01 --data ../shared/data -o WORK --jobs J

and records one JSON object: the rig and its points, the takes written and failed (from the
corpus's corpus.json, with each failure's reason), the frames, the wall seconds and the peak
resident memory of the process tree. Without --rig the built-in face is used.

    python benchmarks/bench_corpus_protocol.py --work /tmp/corpus-builtin --out benchmarks/results/corpus_protocol.json
    python benchmarks/bench_corpus_protocol.py --rig ../shared/data/ict-facekit/ict_face_rig.usdc --work /tmp/corpus-ict
    python benchmarks/bench_corpus_protocol.py --rig RIG --only 'dialog_*_[wrh][aou][lnp]*' --work /tmp/gaits   # the Live Link
                                                                 # performances under walking, running and hopping alone
"""
from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

from bench_calibrate import run_measured
from calibrate_session import DATA
from harness import Recorder, load, parser


def main() -> None:
    args = parser(__doc__)
    args.add_argument("--rig", type=Path, help="a UsdSkel blend-shape rig (default: the built-in face)")
    args.add_argument("--work", type=Path, required=True, help="the corpus folder (emptied first: a fresh run, not a resumed one)")
    args.add_argument("--jobs", type=int, default=2)
    args.add_argument("--data", type=Path, default=DATA)
    args.add_argument("--only", default="", help="only takes whose name matches this glob pattern (simulate --only)")
    args.add_argument("--resume", action="store_true", help="keep --work: an interrupted corpus resumes (the wall time is this run's alone)")
    args = args.parse_args()
    if args.work.exists() and not args.resume:
        shutil.rmtree(args.work)
    command = [sys.executable, "-m", "facedyn.cli", "simulate", "--scale", "standard", "--randomize-tissue", "take",
               "--extra-motions", "true", "--impacts", "true", "--noise", "0.01", "--data", str(args.data), "-o", str(args.work),
               "--jobs", str(args.jobs), "-q"]
    command += ["--rig", str(args.rig)] if args.rig else []
    command += ["--only", args.only] if args.only else []
    with Recorder("bench_corpus_protocol", args) as record:
        load_start = load()
        measured = run_measured(command, args.work.parent / f"{args.work.name}.log")
        index = json.loads((args.work / "corpus.json").read_text()) if (args.work / "corpus.json").is_file() else {}
        takes = index.get("takes", [])
        record({"case": f"the recommended corpus with Live Link performances on {args.rig.name if args.rig else 'the built-in face'}",
                "rig": str(args.rig) if args.rig else "built-in face", "only": args.only, "points": index.get("points"),
                "jobs": args.jobs, "cpu_count": os.cpu_count(), "resumed": args.resume, **measured,
                "takes_written": len(takes), "takes_failed": len(index.get("failed", [])), "failed": index.get("failed", []),
                "takes_resumed": index.get("resumed"),
                "livelink_takes": sum("livelink-face" in str(take["spec"].get("dialog") or "") for take in takes), "frames": index.get("frames"),
                "load_start": load_start, "load_end": load()})


if __name__ == "__main__":
    main()
