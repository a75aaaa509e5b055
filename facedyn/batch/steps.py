"""One batch step in a worker: skip it when current, else run usdfacedyn's own command.

`execute_step` is the Dask task. It never raises: what happened goes back as a result
dict (status ok | skipped | failed | blocked, seconds, output, the one-line error), so one
failing take never stops the others. The command runs in the worker process through
`facedyn.processors.commandline.run_processor`, with its output captured; a lock keeps two threads of one worker from
capturing each other's output (run workers with one thread each, as the local cluster does).
"""
from __future__ import annotations

import io
import threading
import time
from contextlib import redirect_stderr, redirect_stdout

from facedyn.batch.plan import StepPlan
from facedyn.batch.state import input_checksums, is_current, record_step, step_key

_CAPTURE = threading.Lock()
DONE = ("ok", "skipped")


def run_cli(argv: tuple[str, ...]) -> tuple[int, str]:
    """(usdfacedyn's exit code, its last line on stderr: the one-line error when it failed)."""
    from facedyn.processors.commandline import run_processor

    out, err = io.StringIO(), io.StringIO()
    with _CAPTURE, redirect_stdout(out), redirect_stderr(err):
        try:
            code = run_processor(list(argv))
        except SystemExit as exc:  # argparse's usage errors exit
            code = exc.code if isinstance(exc.code, int) else 1
    lines = [line for line in err.getvalue().splitlines() if line.strip()]
    return code, (lines[-1] if lines else f"exit code {code}") if code else ""


def execute_step(plan: StepPlan, previous: dict | None, force: bool = False) -> dict:
    """Run one step of one take unless it is current (or the step before it did not succeed)."""
    started = time.perf_counter()
    result = {"take": plan.take, "step": plan.step, "output": str(plan.output), "key": None, "error": None}

    def finish(status: str, error: str | None = None) -> dict:
        return {**result, "status": status, "error": error, "seconds": round(time.perf_counter() - started, 3)}

    if previous is not None and previous["status"] not in DONE:
        return finish("blocked", f"{previous['step']} did not succeed")
    try:
        checksums = input_checksums(plan)
    except OSError as exc:
        return finish("failed", f"usdfacedyn: error: {exc.filename}: {exc.strerror}")
    result["key"] = step_key(plan, checksums, previous["key"] if previous else None)
    if not force and is_current(plan, result["key"]):
        return finish("skipped")
    made = not plan.folder.exists()
    code, error = run_cli(plan.argv)  # the step's command makes the take folder it writes into
    if code != 0:
        if made and plan.folder.is_dir() and not any(plan.folder.iterdir()):
            plan.folder.rmdir()  # a take that failed at its first step leaves no folder behind
        return finish("failed", error)
    record_step(plan, result["key"], checksums, time.perf_counter() - started)
    return finish("ok")
