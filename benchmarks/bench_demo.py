"""The demo as a user first runs it: its wall time, peak memory and what it leaves on disk (issue 40: <= 90 s, <= 300 MB).

    usdfacedyn demo -o WORK        (the README's first command, after the install)

One record: the wall seconds, the peak resident memory of its process tree, the bytes left in
WORK (the simulated corpus goes to a temporary folder unless --keep-corpus) and the demo's
own summary (its report.json's headline figures, when it writes one).

    python benchmarks/bench_demo.py --work /tmp/demo-out --out benchmarks/results/demo_run.json
"""
from __future__ import annotations

import os
import shutil
import sys
from pathlib import Path

from bench_calibrate import run_measured
from harness import Recorder, load, parser


def folder_bytes(folder: Path) -> int:
    """Bytes of every file under `folder`."""
    return sum(path.stat().st_size for path in folder.rglob("*") if path.is_file())


def main() -> None:
    args = parser(__doc__)
    args.add_argument("--work", type=Path, required=True, help="the demo's output folder (emptied first)")
    args = args.parse_args()
    if args.work.exists():
        shutil.rmtree(args.work)
    command = [sys.executable, "-m", "facedyn.cli", "demo", "-o", str(args.work)]
    with Recorder("bench_demo", args) as record:
        load_start = load()
        measured = run_measured(command, args.work.parent / f"{args.work.name}.log")
        if measured["returncode"] != 0:
            raise SystemExit(f"the demo failed ({measured['returncode']}); its output: {args.work.parent / f'{args.work.name}.log'}")
        record({"case": "usdfacedyn demo, built-in face, demo scale", "cpu_count": os.cpu_count(), **measured,
                "left_on_disk_mb": round(folder_bytes(args.work) / 2**20, 1), "target_seconds": 90, "target_left_mb": 300,
                "load_start": load_start, "load_end": load()})


if __name__ == "__main__":
    main()
