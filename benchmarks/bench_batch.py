"""`usdfacedyn batch` throughput on a local Dask cluster: 1 worker vs 2, and a worker killed.

Simulates --takes walking captures of the built-in face (--seconds each, 120 fps) and a
small removal model (1 epoch on their true dynamics; its accuracy does not matter here),
then runs the steps import, stabilize, remove, preview on every take with 1 and with 2
worker processes in the same run (workers warmed up first: facedyn imported), and once
more on 2 workers killing a busy worker (SIGKILL) after the first finished step. Prints one
JSON object per case (benchmarks/harness.py; --out FILE keeps them for the results page):

    python benchmarks/bench_batch.py --takes 8 [--out benchmarks/results/batch.json]
"""
from __future__ import annotations

import os
import shutil
import signal
import time
from pathlib import Path

from harness import Recorder, parser
from spill import scratch_folder

from facedyn.batch.cluster import open_client, run_steps
from facedyn.batch.plan import Models, plan_batch
from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import save_model
from facedyn.dynamics.training import TrainConfig, train_removal
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.usd.corpus_files import write_simulated_take

STEPS = ("import", "stabilize", "remove", "preview")


def make_shots(folder: Path, takes: int, seconds: float) -> tuple[list[str], Path]:
    """(capture paths, removal model path)."""
    rig = default_face()
    sims = [simulate_take(rig, TakeSpec(f"shot{i}", "walk", "smile", duration_s=seconds, seed=i)) for i in range(takes)]
    captures = []
    for sim in sims:
        write_simulated_take(folder / "sim" / sim.spec.name, sim, rig)
        captures.append(str(shutil.copy(folder / "sim" / sim.spec.name / "capture.usdc", folder / f"{sim.spec.name}.usdc")))
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices)
    training = [TrainingSequence(s.spec.name, s.captured, s.fps, s.skull_translate, s.skull_orient, "skull", s.offsets) for s in sims[:2]]
    model = save_model(train_removal(training, face, TrainConfig(epochs=1, target="truth")), folder / "actor.removal")
    return captures, model


def warm_up() -> None:
    """What every step imports, so that the timing is the steps' work."""
    import facedyn.cli  # noqa: F401
    import facedyn.dynamics.removal  # noqa: F401
    import facedyn.usd  # noqa: F401


def run(captures: list[str], model: Path, out: Path, workers: int, kill: bool) -> dict:
    takes = plan_batch(captures, out, STEPS, Models(removal=model))
    with open_client(workers=workers) as client:
        client.run(warm_up)
        pids = client.run(os.getpid)
        killed: list[str] = []

        def kill_a_busy_worker(result, results):
            busy = [address for address, keys in client.processing().items() if keys and address in pids]
            if kill and not killed and busy:
                os.kill(pids[busy[0]], signal.SIGKILL)
                killed.append(busy[0])

        started = time.perf_counter()
        results = run_steps(client, takes, on_result=kill_a_busy_worker)
        seconds = time.perf_counter() - started
    done = {r["take"] for r in results} - {r["take"] for r in results if r["status"] not in ("ok", "skipped")}
    return {"workers": workers, "takes": len(takes), "steps": list(STEPS), "takes_completed": len(done), "seconds": round(seconds, 2),
            "takes_per_minute": round(60 * len(takes) / seconds, 2), "worker_killed": bool(killed)}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--takes", type=int, default=8)
    arguments.add_argument("--seconds", type=float, default=1.0, help="length of each capture")
    args = arguments.parse_args()
    scratch = scratch_folder()
    captures, model = make_shots(scratch, args.takes, args.seconds)
    timed = {}
    with Recorder("bench_batch", args) as emit:
        for workers in (1, 2):
            timed[workers] = run(captures, model, scratch / f"out{workers}", workers, kill=False)
            emit({"case": "throughput", "cores": os.cpu_count(), "capture_seconds": args.seconds, **timed[workers]})
        emit({"case": "speedup", "workers": [1, 2], "throughput_ratio": round(timed[1]["seconds"] / timed[2]["seconds"], 3)})
        emit({"case": "worker_killed", "capture_seconds": args.seconds, **run(captures, model, scratch / "killed", 2, kill=True)})


if __name__ == "__main__":
    main()
