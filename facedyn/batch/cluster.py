"""Running a batch's steps on a Dask cluster: one task per (take, step), chained per take.

`open_client` starts an embedded LocalCluster (worker processes of one thread each, one per
core unless told, their numeric libraries and OpenCL single-threaded too) or connects to an existing scheduler (`dask scheduler` / `dask worker
--nthreads 1`, or a dask-jobqueue cluster on Slurm/PBS/SGE: pass its scheduler address).
Steps of one take run in order, takes run side by side. A task whose worker dies is
rescheduled by Dask on another worker (up to the scheduler's allowed-failures), and every
output is written atomically, so a lost worker leaves nothing half-written.
"""
from __future__ import annotations

import os
import time
import uuid
from contextlib import contextmanager
from typing import Callable, Iterator

from facedyn.batch.plan import StepPlan
from facedyn.batch.steps import DONE, execute_step

RETRIES = 2
# One thread per local worker process (one process per core): torch and BLAS (OMP), PoCL's
# OpenCL CPU device (old and new names); a value already in the environment wins.
SINGLE_THREADED = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "POCL_MAX_PTHREAD_COUNT", "POCL_CPU_MAX_CU_NUM")  # resubmissions of a task that raised (a step itself never raises; see steps.execute_step)

ResultCallback = Callable[[dict, list[dict]], None]  # (the step's result, every result so far)


@contextmanager
def open_client(workers: int | None = None, scheduler: str | None = None) -> Iterator:
    """A dask.distributed Client: on the scheduler at ``scheduler`` (tcp://HOST:PORT), or on a
    local cluster of ``workers`` processes (default: one per core) that closes afterwards."""
    from distributed import Client, LocalCluster

    if scheduler:
        with Client(scheduler) as client:
            yield client
        return
    count = workers or os.cpu_count() or 1
    env = {name: os.environ.get(name, "1") for name in SINGLE_THREADED}
    with LocalCluster(n_workers=count, threads_per_worker=1, processes=True, dashboard_address=":0", env=env) as cluster, \
            Client(cluster) as client:
        yield client


def run_steps(client, takes: list[list[StepPlan]], force: bool = False, on_result: ResultCallback | None = None) -> list[dict]:
    """Every step of every take on the cluster; the results in the order of ``takes``' steps."""
    from distributed import as_completed

    batch = uuid.uuid4().hex[:8]
    previous_of, plan_of, futures = {}, {}, []
    for plans in takes:
        previous = None
        for plan in plans:
            future = client.submit(execute_step, plan, previous, force, key=f"facedyn-{plan.take}-{plan.step}-{batch}", pure=False,
                                   retries=RETRIES)
            previous_of[future.key], plan_of[future.key] = previous, plan
            futures.append(future)
            previous = future
    done: dict[str, dict] = {}
    for future in as_completed(futures):
        done[future.key] = _result(future, previous_of[future.key], plan_of[future.key], done)
        if on_result is not None:
            on_result(done[future.key], list(done.values()))
    return [done[key] for key in plan_of]


def _result(future, previous, plan: StepPlan, done: dict) -> dict:
    """The step's result dict, also when its task could not run (its worker kept dying)."""
    if future.status == "finished":
        return future.result()
    failed_before = previous is not None and done.get(previous.key, {}).get("status") not in DONE
    status, error = ("blocked", "an earlier step did not succeed") if failed_before else ("failed", f"task lost: {future.exception()!r}")
    return {"take": plan.take, "step": plan.step, "output": str(plan.output), "key": None, "status": status, "error": error, "seconds": 0.0}


def batch_report(takes: list[list[StepPlan]], results: list[dict], seconds: float, workers: int) -> dict:
    """The JSON report: one entry per take with its steps' status, seconds, output and error."""
    by_step = {(r["take"], r["step"]): r for r in results}
    entries = []
    for plans in takes:
        steps = [{k: v for k, v in by_step[(p.take, p.step)].items() if k not in ("take", "key")} for p in plans]
        entries.append({"take": plans[0].take, "folder": str(plans[0].folder),
                        "status": "ok" if all(s["status"] in DONE for s in steps) else "failed", "steps": steps})
    return {"succeeded": all(e["status"] == "ok" for e in entries), "takes": entries, "workers": workers,
            "seconds": round(seconds, 2)}


def progress_printer(takes: list[list[StepPlan]], stream) -> ResultCallback:
    """A callback that prints one line per finished step: takes and steps done so far."""
    total_steps = sum(len(p) for p in takes)
    steps_of = {plans[0].take: len(plans) for plans in takes}
    started = time.perf_counter()

    def show(result: dict, results: list[dict]) -> None:
        finished = {}
        for r in results:
            finished[r["take"]] = finished.get(r["take"], 0) + 1
        takes_done = sum(1 for take, count in finished.items() if count == steps_of[take])
        note = f": {result['error']}" if result["error"] else ""
        print(f"batch: {takes_done}/{len(takes)} takes, {len(results)}/{total_steps} steps ({time.perf_counter() - started:.0f} s) "
              f"{result['take']} {result['step']} {result['status']} in {result['seconds']:.1f} s{note}", file=stream, flush=True)

    return show
