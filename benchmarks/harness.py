"""What every benchmark shares: its arguments for where results go, and one JSON record per case.

A figure is only worth quoting with what produced it, so each record carries the command
line, the commit (``-dirty`` when the work tree had changes), the date, the machine and its
load beside the case's own fields. Records go to stdout, one JSON object a line, as they are
measured; with ``--out FILE`` the run's records are also written to FILE (a JSON list,
written atomically when the run ends), which is how a run enters ``benchmarks/results/`` and
from there ``docs/results.md`` (``python benchmarks/results.py``).

    from harness import Recorder, parser
    args = parser(__doc__).parse_args()          # adds --out and --note to the benchmark's own flags
    with Recorder("bench_x", args) as record:
        record({"case": "removal", "frames_per_second": 1971.2,
                "obtained": {"skull": "solved", "test data": "facedyn.sim.tissue"}})
"""
from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
CONTEXT_FIELDS = ("benchmark", "case", "command", "commit", "date", "machine", "load")


def parser(doc: str | None) -> argparse.ArgumentParser:
    """An argument parser with the flags every benchmark takes (add the benchmark's own after)."""
    result = argparse.ArgumentParser(description=(doc or "").strip().splitlines()[0] if doc else None)
    result.add_argument("--out", type=Path, help=f"also write this run's records to FILE as a JSON list (e.g. {RESULTS.relative_to(ROOT)}/NAME.json)")
    result.add_argument("--note", default="", help="recorded in every record: what else shared the machine, why the run was made")
    return result


def commit() -> str:
    """The checked-out commit, with -dirty when tracked files differ from it ('unknown' outside git)."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short=7", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


def machine() -> str:
    """CPU model, cores and Python: enough to tell two machines' figures apart."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores, Python {platform.python_version()}"


def load() -> str:
    """The 1, 5 and 15 minute load averages, as `uptime` prints them."""
    try:
        return "load average " + ", ".join(f"{value:.2f}" for value in os.getloadavg())
    except OSError:
        return "unknown"


def command_line() -> str:
    """How this benchmark was started, its script relative to the repository."""
    script = Path(sys.argv[0]).resolve()
    argv = [(script.relative_to(ROOT) if script.is_relative_to(ROOT) else script).as_posix()] + sys.argv[1:]
    return "python " + shlex.join(argv)


def context(benchmark: str, note: str = "", at_commit: str | None = None) -> dict:
    """The fields that say where and when a record was measured (the commit: at_commit, else now)."""
    fields = {"benchmark": benchmark, "command": command_line(), "commit": at_commit or commit(),
              "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"), "machine": machine(), "load": load()}
    if note:
        fields["note"] = note
    return fields


def write_records(path: Path, records: list[dict]) -> None:
    """Write records as a JSON list, atomically (a reader never sees half a file)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        umask = os.umask(0)
        os.umask(umask)
        os.fchmod(handle, 0o666 & ~umask)
        with os.fdopen(handle, "w") as stream:
            json.dump(records, stream, indent=1)
            stream.write("\n")
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


class Recorder:
    """Prints each case's record with its context as it is measured; with --out, keeps them for the file."""

    def __init__(self, benchmark: str, args: argparse.Namespace | None = None):
        self.benchmark = benchmark
        self.out = getattr(args, "out", None)
        self.note = getattr(args, "note", "")
        self.records: list[dict] = []
        self.commit = commit()  # the code measured is the code at the start, whatever is committed meanwhile

    def __call__(self, case: dict) -> dict:
        if "case" not in case:
            raise ValueError(f"{self.benchmark}: a record needs a 'case' field, got {sorted(case)}")
        record = {**context(self.benchmark, self.note, self.commit), **case}
        print(json.dumps(record), flush=True)
        self.records.append(record)
        return record

    def __enter__(self) -> "Recorder":
        return self

    def __exit__(self, kind, value, traceback) -> None:
        if kind is None and self.out is not None:
            write_records(self.out, self.records)
