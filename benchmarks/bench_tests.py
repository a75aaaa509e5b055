"""Wall time of the test suite's tiers: the fast tier for everyday work, or the whole suite as CI runs it.

Runs pytest in a child process from the repository root and records its wall time, its CPU
time (user + system, which a loaded machine changes far less than the wall time), exit
status and summary line, beside the load average before and after. The fast tier's target
is 2 minutes on 2 cores.

    python benchmarks/bench_tests.py [--tier fast|all] [--out benchmarks/results/tests_fast.json]
"""
from __future__ import annotations

import re
import resource
import subprocess
import sys
import time

from harness import ROOT, Recorder, load, parser

TIERS = {"fast": ["-m", "not slow"], "all": []}


def main() -> int:
    arguments = parser(__doc__)
    arguments.add_argument("--tier", choices=sorted(TIERS), default="fast")
    args = arguments.parse_args()
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *TIERS[args.tier]]
    with Recorder("tests", args) as record:
        before = load()
        started = time.perf_counter()
        result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
        seconds = time.perf_counter() - started
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        summary = next((line for line in reversed(result.stdout.splitlines()) if re.search(r"\d+ (passed|failed)", line)), "")
        failed = [line.split()[1] for line in result.stdout.splitlines() if line.startswith(("FAILED ", "ERROR "))]
        record({"case": f"{args.tier} tier", "id": f"tests-{args.tier}", "pytest": " ".join(["python3", *command[1:]]), "seconds": round(seconds, 1),
                "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 1),
                "exit_status": result.returncode, "summary": summary.strip("= "), "load_before": before, **({"failed": failed} if failed else {})})
    return result.returncode


if __name__ == "__main__":
    sys.exit(main())
