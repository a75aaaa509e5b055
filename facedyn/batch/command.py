"""`usdfacedyn batch`: many captures through the pipeline's steps on a Dask cluster.

    usdfacedyn batch CAPTURES... -o OUTDIR --steps import,stabilize,remove,synthesize,preview
        [--actor A] [--removal-model F] [--synthesis-model H] [--skull-motion M]
        [--workers N | --scheduler tcp://HOST:PORT] [--force] [--json]

Each capture (a mesh cache, a glob pattern, or a shot list: a .txt file with one path per
line) becomes OUTDIR/<name>/ with its take.usda. Each step is the processor of that name with
the flags it declares: `--removal-model` is remove's `--model`, `--synthesis-model` synthesize's
(`--model` is the old spelling of `--removal-model`, kept as a deprecated alias). Exit code 0 when every take succeeded, 1
when any failed (the others still ran), 2 for a usage error.
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from facedyn.batch.plan import STEP_OPTIONS, STEPS, Models, parse_steps, plan_batch
from facedyn.errors import UsageError

EXIT_OK, EXIT_FAILURE = 0, 1


def add_batch_arguments(parser) -> None:
    """The batch subcommand's arguments (the handler is `run_batch`)."""
    parser.add_argument("captures", nargs="+", metavar="CAPTURE", help="mesh caches, glob patterns, or shot lists (.txt: one path per line)")
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUTDIR", help="folder of the takes (OUTDIR/<name>/take.usda)")
    parser.add_argument("--steps", default=",".join(STEPS), help=f"comma-separated steps, in order (default: {','.join(STEPS)})")
    for option in STEP_OPTIONS:  # each a step's parameter (facedyn.batch.plan)
        parser.add_argument(option.flag, dest=option.field, metavar=option.metavar, help=option.help)
        if option.alias:
            parser.add_argument(option.alias, dest=f"{option.field}_alias", metavar=option.metavar, help=f"deprecated alias of {option.flag}")
    where = parser.add_mutually_exclusive_group()
    where.add_argument("--workers", type=int, metavar="N", help="worker processes of the embedded local cluster (default: one per core)")
    where.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                       help="submit to a running Dask scheduler (dask scheduler + dask worker --nthreads 1, or dask-jobqueue on Slurm/PBS/SGE)")
    parser.add_argument("--force", action="store_true", help="redo every step, even those whose outputs are current")
    parser.add_argument("--json", action="store_true", help="print a JSON report (one entry per take and step)")


def models_from(args) -> Models:
    """The steps' models and motions from batch's options; a removal model's shipped name (default) as its file."""
    from facedyn.models import resolve_model

    given = {}
    for option in STEP_OPTIONS:
        value = getattr(args, option.field)
        if option.alias and getattr(args, f"{option.field}_alias") is not None:
            if value is not None:
                raise UsageError(f"{option.alias} is the old name of {option.flag}: give one of them")
            print(f"usdfacedyn: batch {option.alias} is deprecated and will be removed; use {option.flag} (the same model)", file=sys.stderr)
            value = getattr(args, f"{option.field}_alias")
        if not value:
            value = None
        elif option.shipped:
            value = resolve_model(value)  # a shipped model's name (default) as its file
        elif option.file:
            value = Path(value)
        given[option.field] = value
    return Models(**given)


def run_batch(args) -> int:
    """Plan, run on the cluster, report; the exit code says whether every take succeeded."""
    from facedyn.batch.cluster import batch_report, open_client, progress_printer, run_steps

    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be at least 1, got {args.workers}")
    takes = plan_batch(args.captures, args.output, parse_steps(args.steps), models_from(args))
    output = Path(args.output)
    if output.exists() and not output.is_dir():
        raise UsageError(f"-o {output}: is a file; -o names the folder of the takes")
    made = [p for p in [output, *output.parents] if not p.exists()]  # innermost first
    output.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    try:
        with open_client(args.workers, args.scheduler) as client:
            workers = len(client.scheduler_info()["workers"])
            results = run_steps(client, takes, args.force, None if args.json else progress_printer(takes, sys.stderr))
    finally:
        for folder in made:  # every take failed before writing anything: no empty OUTDIR left behind
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
    report = batch_report(takes, results, time.perf_counter() - started, workers)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report))
    return EXIT_OK if report["succeeded"] else EXIT_FAILURE


def format_report(report: dict) -> str:
    failed = [e for e in report["takes"] if e["status"] != "ok"]
    lines = [f"batch: {len(report['takes']) - len(failed)}/{len(report['takes'])} takes succeeded on {report['workers']} workers "
             f"in {report['seconds']} s"]
    for entry in failed:
        step = next(s for s in entry["steps"] if s["status"] not in ("ok", "skipped"))
        lines.append(f"  FAILED {entry['take']} at {step['step']}: {step['error']}")
    return "\n".join(lines)
