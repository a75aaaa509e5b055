"""Time and memory of `usdfacedyn calibrate` on issue 37's session: 70 takes on a 2.7k-point
ARKit-named rig, the corpus included (target: 45 minutes on 2 cores).

The session is calibrate_session.py's (made in --session when it is not there yet; the first
--expressions' takes, 7 each). calibrate runs as its own process as a user runs it:

    usdfacedyn calibrate SESSION/takes/*/take.usda --rig SESSION/rig.usdc --data ../shared/data -o WORK \
        --budget-minutes M --jobs J [--epochs E] [--corpus-scale S] [--corpus-only PATTERN]

One record per run: the wall seconds, each stage's (calibration.json's), the peak resident
memory of the whole process tree (calibrate and its corpus workers, sampled every 0.5 s)
and of its largest process, the corpus's takes written and failed, F's minutes and epochs
(the most allowed, trained, its measured pairs a second), the response's ridge, the candidates'
figures and the chosen removal, and the machine's load at the start and the end. Figures
are only worth quoting from an idle machine (say what else ran with --note).

    python benchmarks/bench_calibrate.py --session /tmp/bench/session70 --work /tmp/bench/calibrate70 \
        --out benchmarks/results/calibrate.json                                # the issue's target
    python benchmarks/bench_calibrate.py --session /tmp/bench/session70 --expressions 2 --budget-minutes 8 \
        --work /tmp/bench/calibrate14                                          # a quick try: 14 takes
"""
from __future__ import annotations

import json
import os
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import psutil
from calibrate_session import DATA, PLATFORMS, MOCAP, make_session, take_roots
from harness import Recorder, load, parser

TAKES_PER_EXPRESSION = len(PLATFORMS) + len(MOCAP)


def tree_rss(process: psutil.Process) -> int:
    """Resident bytes of a process and all its descendants now (0 for those that are gone)."""
    total = 0
    try:
        members = [process] + process.children(recursive=True)
    except psutil.NoSuchProcess:
        return 0
    for member in members:
        try:
            total += member.memory_info().rss
        except psutil.NoSuchProcess:
            pass
    return total


def run_measured(command: list[str], log: Path) -> dict:
    """Run `command` (its output to `log`), sampling its process tree's memory; wall seconds, peaks, exit code."""
    started = time.perf_counter()
    with log.open("w") as stream:
        child = subprocess.Popen(command, stdout=stream, stderr=subprocess.STDOUT)
        watched, peak = psutil.Process(child.pid), 0
        while child.poll() is None:
            peak = max(peak, tree_rss(watched))
            time.sleep(0.5)
    seconds = time.perf_counter() - started
    largest = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss * 1024  # Linux: KiB, the largest process waited for
    return {"returncode": child.returncode, "wall_seconds": round(seconds, 1), "peak_tree_rss_mb": round(peak / 2**20, 1),
            "peak_process_rss_mb": round(largest / 2**20, 1)}


def main() -> None:
    args = parser(__doc__)
    args.add_argument("--session", type=Path, required=True, help="calibrate_session.py's folder (made there when missing)")
    args.add_argument("--expressions", type=int, default=10, choices=range(1, 11), metavar="1..10", help="held expressions: 7 takes each")
    args.add_argument("--work", type=Path, required=True, help="calibrate's output folder (emptied first: a fresh run, not a resumed one)")
    args.add_argument("--budget-minutes", type=float, default=45.0)
    args.add_argument("--epochs", type=int, default=None, help="pin F's epochs (default: the budget's)")
    args.add_argument("--corpus-scale", default="standard", choices=("demo", "standard"))
    args.add_argument("--corpus-only", default="", help="calibrate --corpus-only")
    args.add_argument("--jobs", type=int, default=2)
    args.add_argument("--data", type=Path, default=DATA)
    args = args.parse_args()

    roots = take_roots(args.session, args.expressions) if (args.session / "session.json").is_file() else []
    if not roots or not all(root.is_file() for root in roots):
        make_session(args.session, args.data, args.expressions, args.jobs)
        roots = take_roots(args.session, args.expressions)
    if args.work.exists():
        shutil.rmtree(args.work)
    args.work.mkdir(parents=True)
    command = [sys.executable, "-m", "facedyn.cli", "calibrate", *map(str, roots), "--rig", str(args.session / "rig.usdc"),
               "--data", str(args.data), "-o", str(args.work), "--budget-minutes", f"{args.budget_minutes:g}", "--jobs", str(args.jobs),
               "--corpus-scale", args.corpus_scale, "--json"]
    command += ["--epochs", str(args.epochs)] if args.epochs else []
    command += ["--corpus-only", args.corpus_only] if args.corpus_only else []
    with Recorder("bench_calibrate", args) as record:
        load_start = load()
        measured = run_measured(command, args.work.parent / f"{args.work.name}.log")
        if measured["returncode"] != 0:
            raise SystemExit(f"calibrate failed ({measured['returncode']}); its output: {args.work.parent / f'{args.work.name}.log'}")
        result = json.loads((args.work / "calibration.json").read_text())
        budget, family = result["budget"], result["family"]
        record({
            "case": f"calibrate, {len(roots)} session takes, {result['corpus']['takes']} corpus takes, budget {args.budget_minutes:g} min",
            "session_takes": len(roots), "rig_points": json.loads((args.session / "session.json").read_text())["rig"]["points"],
            "corpus_scale": args.corpus_scale, "corpus_only": args.corpus_only, "jobs": args.jobs, "cpu_count": os.cpu_count(),
            "budget_minutes": args.budget_minutes, **measured,
            "stage_seconds": result["stage_seconds"], "corpus_takes_written": result["corpus"]["takes"],
            "corpus_takes_failed": result["corpus"]["failed"], "corpus_frames": result["corpus"]["frames"],
            "max_epochs": budget["epochs"], "epochs_given": budget["epochs_given"],
            "training_seconds_planned": budget["training_seconds_planned"], "epochs_trained": family["epochs"],
            "family_seconds": family["seconds"], "first_epoch_seconds": family["first_epoch_seconds"],
            "median_epoch_seconds": family["median_epoch_seconds"], "pairs_per_second": family["pairs_per_second"],
            "ridge": result["response"]["ridge"], "chosen": result["chosen"],
            "session_motion_left": {name: c["session_motion_left"] for name, c in result["candidates"].items()},
            "load_start": load_start, "load_end": load(),
            "obtained": {"session": "calibrate_session.py: facedyn.sim.tissue, one actor's TissueParams.random, tracker noise, "
                                    "plain captures imported and stabilized with --actor", "rig": "arkit_rig.py (ICT decimated)"},
        })


if __name__ == "__main__":
    main()
