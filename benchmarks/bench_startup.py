"""Start-up: how long `usdfacedyn` takes to answer what needs no work, and `inspect MODEL`.

Each case runs the console command in a fresh interpreter (`python -m facedyn.cli ...`,
what the `usdfacedyn` script does) --repeat times; the best run is the figure (the machine
may be shared: the load average before and after is recorded beside it). `python -c pass`
is measured the same way, the floor every command pays. Beside the wall time, the CPU time
(user + system) of the best run: on a shared machine it is the steadier figure. The models inspected are F with the
default architecture on a small face and on an 11,236-point mesh (344 samples, bench_model_load_memory's), written
to a scratch folder.

Targets (issue 40): --version and --help <= 0.3 s; inspect MODEL <= 0.5 s.

    python benchmarks/bench_startup.py [--repeat 7] [--out benchmarks/results/startup.json]
"""
from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench_model_load_memory import build
from harness import Recorder, parser

TARGETS = {"--version": 0.3, "--help": 0.3, "inspect MODEL": 0.5}


def small_model(path: Path) -> Path:
    import numpy as np
    import torch

    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.modelfile import DynamicsModel, save_model
    from facedyn.dynamics.network import Network, removal_spec
    from facedyn.performance import Topology

    rows, cols = 10, 8
    ys, xs = np.mgrid[0:rows, 0:cols].astype(np.float64)
    points = np.stack([xs, ys, np.sin(xs / 3.0)], -1).reshape(-1, 3)
    a = (np.arange(rows - 1)[:, None] * cols + np.arange(cols - 1)[None, :]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + cols + 1], 1), np.stack([a, a + cols + 1, a + cols], 1)])
    topology = Topology(np.full(len(tris), 3, np.int32), tris.ravel().astype(np.int32))
    face = FaceSetup.build(topology, points, rigid_vertices=np.arange(2 * cols), sample_count=12)
    torch.manual_seed(0)
    return save_model(DynamicsModel("removal", Network(removal_spec()), face, 120.0, {"skull": 10, "skin": 10, "target": 10}), path)


def best_of(argv: list[str], repeat: int) -> tuple[float, list[float], float]:
    """The best wall seconds, every run's, and the best CPU seconds (user + system: what a busy machine inflates least)."""
    runs, cpu = [], []
    for _ in range(repeat):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        started = time.perf_counter()
        done = subprocess.run(argv, capture_output=True, text=True)
        runs.append(time.perf_counter() - started)
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu.append(after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime)
        if done.returncode != 0:
            raise SystemExit(f"{' '.join(argv)} failed: {done.stderr.strip()}")
    return min(runs), runs, min(cpu)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--repeat", type=int, default=7)
    args = arguments.parse_args()
    cli = [sys.executable, "-m", "facedyn.cli"]
    with tempfile.TemporaryDirectory(prefix="facedyn-bench-startup-") as scratch, Recorder("bench_startup", args) as record:
        model = small_model(Path(scratch) / "actor.removal")
        large = Path(scratch) / "ict.removal"
        build(large, 106, (128, 128), 344)
        cases = {"python -c pass": [sys.executable, "-c", "pass"], "--version": [*cli, "--version"], "--help": [*cli, "--help"],
                 "list": [*cli, "list"], "stabilize --help": [*cli, "stabilize", "--help"], "inspect MODEL": [*cli, "inspect", str(model)],
                 "inspect MODEL (F on an 11k-point mesh)": [*cli, "inspect", str(large)]}
        for name, argv in cases.items():
            load_before = os.getloadavg()
            best, runs, cpu = best_of(argv, args.repeat)
            case = {"case": f"start-up: {name}", "seconds": round(best, 3), "seconds_all_runs": [round(r, 3) for r in runs],
                    "cpu_seconds": round(cpu, 3),
                    "cpu_count": os.cpu_count(),
                    "load_average": {"before": [round(x, 2) for x in load_before], "after": [round(x, 2) for x in os.getloadavg()]}}
            if name.split(" (")[0] in TARGETS:
                target = TARGETS[name.split(" (")[0]]
                case.update(target_seconds=target, meets_target=best <= target)
            record(case)


if __name__ == "__main__":
    main()
