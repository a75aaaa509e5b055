"""Wall time of the test suite's tiers: the fast tier for everyday work, or the whole suite as CI runs it.

Runs pytest in a child process from the repository root and records its wall time, its CPU
time (user + system of pytest and its workers, which a loaded machine changes far less than
the wall time), the pytest-xdist worker processes it ran on, exit status and summary line,
beside the load average before and after. The fast tier's target is 2 minutes on 2 cores,
the whole suite's 5 minutes.

    python benchmarks/bench_tests.py [--tier fast|all] [--workers N|auto] [--out benchmarks/results/tests_fast.json]
"""
from __future__ import annotations

import configparser
import re
import resource
import subprocess
import sys
import time

from harness import ROOT, Recorder, load, parser

TIERS = {"fast": ["-m", "not slow"], "all": []}


def default_workers() -> str:
    """The worker processes the suite runs on when not told: setup.cfg's [tool:pytest] addopts -n (0: in-process)."""
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    options = config.get("tool:pytest", "addopts", fallback="").split()
    return options[options.index("-n") + 1] if "-n" in options[:-1] else "0"


def main() -> int:
    arguments = parser(__doc__)
    arguments.add_argument("--tier", choices=sorted(TIERS), default="fast")
    arguments.add_argument("--workers", default=default_workers(),
                           help="pytest-xdist worker processes: a count, auto (one a core) or 0 (in pytest's process); default: setup.cfg's, %(default)s")
    args = arguments.parse_args()
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-n", args.workers, *TIERS[args.tier]]
    with Recorder("tests", args) as record:
        before = load()
        started = time.perf_counter()
        result = subprocess.run(command, cwd=ROOT, capture_output=True, text=True)
        seconds = time.perf_counter() - started
        usage = resource.getrusage(resource.RUSAGE_CHILDREN)
        summary = next((line for line in reversed(result.stdout.splitlines()) if re.search(r"\d+ (passed|failed)", line)), "")
        failed = [line.split()[1] for line in result.stdout.splitlines() if line.startswith(("FAILED ", "ERROR "))]
        record({"case": f"{args.tier} tier", "id": f"tests-{args.tier}", "pytest": " ".join(["python3", *command[1:]]), "workers": args.workers, "seconds": round(seconds, 1),
                "cpu_seconds": round(usage.ru_utime + usage.ru_stime, 1),
                "exit_status": result.returncode, "summary": summary.strip("= "), "load_before": before, **({"failed": failed} if failed else {})})
    return result.returncode


if __name__ == "__main__":
    sys.exit(main())
