"""The command line of a declared processor, generated from its declaration.

`usdfacedyn` (facedyn.cli) adds one subcommand per processor with `add_processor_parser`;
`run_processor` runs one processor's command line on its own (batch steps do, in workers).
Every failure ends as one line on stderr (and as JSON on stdout for --json runs), with exit
code 1 for bad input and 2 for usage errors.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
import traceback
from contextlib import contextmanager
from pathlib import Path

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2
OUTPUT_FLAG, ATTACH_FLAG, QUIET_FLAG = "-o", "--attach", "-q"  # every processor's (batch writes its steps' command lines with them)


class Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line and exit code 2."""

    def error(self, message: str):
        raise ArgparseError(f"{self.prog}: {message} (see --help)")


class ArgparseError(Exception):
    pass


def run_guarded(argv: list[str], build) -> int:
    """Parse argv with the parser `build()` makes and run its handler; every failure ends as one line (exit 1 or 2)."""
    debug, as_json = "--debug" in argv, "--json" in argv
    # Read .usdc values with pread, not mmap: a mapped multi-GB take counts every page a
    # streaming step has touched in its resident memory; read, it stays a chunk's worth.
    os.environ.setdefault("USDC_USE_PREAD", "1")
    from facedyn.errors import FacedynError, UsageError

    try:
        with signals_raise():
            args = build().parse_args(argv)
            # USD (0.2-0.3 s) loads once a command that uses it runs, not for --help, --version or a usage
            # error; a command that sets uses_usd=False imports facedyn.usd itself where it needs it.
            if getattr(args, "uses_usd", True):
                try:
                    import facedyn.usd  # noqa: F401  (registers the USD plugins; fails with a clear message if it cannot)
                except Exception as exc:
                    return fail(f"usdfacedyn: error: {exc}", EXIT_FAILURE, as_json)
            return args.handler(args)
    except Interrupted as exc:
        return fail(f"usdfacedyn: interrupted ({exc.name})", 128 + exc.number, as_json)
    except KeyboardInterrupt:
        return fail("usdfacedyn: interrupted", 130, as_json)
    except ArgparseError as exc:
        return fail(f"usdfacedyn: usage error: {exc}", EXIT_USAGE, as_json)
    except BrokenPipeError:
        return _reader_went_away()
    except Exception as exc:  # every failure ends as one line; --debug shows the traceback
        if debug:
            traceback.print_exc()
        if isinstance(exc, UsageError):
            return fail(f"usdfacedyn: usage error: {exc}", EXIT_USAGE, as_json)
        if isinstance(exc, FacedynError):
            return fail(f"usdfacedyn: error: {exc}", EXIT_FAILURE, as_json)
        if isinstance(exc, OSError):
            message = f"{exc.filename or ''}: {exc.strerror or exc}".lstrip(": ")
            return fail(f"usdfacedyn: error: {message}", EXIT_FAILURE, as_json)
        return fail(f"usdfacedyn: internal error: {type(exc).__name__}: {exc} (rerun with --debug for a traceback)",
                     EXIT_FAILURE, as_json)


class Interrupted(BaseException):
    """SIGTERM or SIGHUP arrived: raised so every `finally` runs (temporary files removed) before exiting."""

    def __init__(self, number: int):
        super().__init__(number)
        self.number = number
        self.name = signal.Signals(number).name


@contextmanager
def signals_raise():
    """While inside, SIGTERM and SIGHUP raise Interrupted and SIGINT KeyboardInterrupt (main thread only).

    A farm scheduler stops a job with SIGTERM; Python's default would end the process at
    once, leaving a half-written `.NAME.PID.XXXX.usdc` beside the output. Raising instead
    unwinds through the writers' cleanup. The previous handlers come back on exit.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def interrupt(number, _frame):
        raise Interrupted(number)

    previous = {number: signal.signal(number, interrupt) for number in (signal.SIGTERM, signal.SIGHUP)}
    previous[signal.SIGINT] = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def _reader_went_away() -> int:
    """stdout's reader closed the pipe (`usdfacedyn inspect MODEL | head -1`): stop quietly, as Unix tools do.

    stdout is pointed at /dev/null so that flushing it at exit does not raise again; the
    exit code is the shell's for a process ended by SIGPIPE.
    """
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):  # stdout is no file descriptor (captured in a batch worker)
        pass
    return 128 + signal.SIGPIPE


def fail(message: str, code: int, as_json: bool) -> int:
    """One line on stderr; on --json runs the same error as JSON on stdout."""
    # One line, and printable on any stream: undecodable path bytes are shown escaped (\udce9 -> \\udce9).
    message = " ".join(message.split()).encode("utf-8", "backslashreplace").decode("utf-8")
    print(message, file=sys.stderr)
    if as_json:
        print(json.dumps({"error": message, "exit_code": code}))
    return code


def run_processor(argv: list[str]) -> int:
    """Run one processor's command line (argv[0] is its name), as `usdfacedyn` would."""
    from facedyn.processors import registry

    def build():
        parser = Parser(prog="usdfacedyn")
        commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
        commands.required = True
        add_processor_parser(commands, registry.load(argv[0]))
        return parser

    return run_guarded([str(a) for a in argv], build)


def common_flags(p: argparse.ArgumentParser, json_help: str = "print a JSON report on stdout") -> None:
    p.add_argument("--json", action="store_true", help=json_help)
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)


def add_processor_parser(commands, processor) -> None:
    """A subcommand generated from a processor's declaration."""
    reads, writes = processor.reads, processor.writes
    p = commands.add_parser(processor.name, help=processor.summary, description=processor.summary)
    if reads.what != "nothing":
        p.add_argument("inputs", nargs="+" if reads.many else None, type=Path, metavar=reads.metavar, help=reads.help or None)
    output_help = writes.help + (f" (default: {writes.default})" if writes.default else "")
    p.add_argument(OUTPUT_FLAG, "--output", type=Path, required=writes.default is None, default=writes.default and Path(writes.default),
                   metavar=writes.metavar, help=output_help)
    if writes.what == "layer" and writes.attach:
        p.add_argument(ATTACH_FLAG, type=Path, metavar="ROOT", help="place the output in ROOT's subLayers by its role")
    if writes.what == "layer" or reads.frame_range:
        p.add_argument("--frames", type=_frame_range, metavar="FIRST:LAST", help="only these frames (inclusive time codes)")
    p.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE", help="set a parameter by name")
    p.add_argument("--dry-run", action="store_true", help="read and check the inputs and parameters, write nothing")
    p.add_argument(QUIET_FLAG, "--quiet", action="store_true", help="no progress output")
    common_flags(p)
    options = p.add_argument_group(f"{processor.name} parameters (also -p KEY=VALUE)")
    for param in processor.parameters:
        if param.required:
            help_text = f"{param.help} (required)"
        elif param.default in (None, ""):
            help_text = param.help
        else:
            help_text = f"{param.help} (default: {param.default})"
        if param.choices:
            help_text = f"{help_text}; one of {', '.join(map(str, param.choices))}"
        options.add_argument(param.flag, dest=f"param_{param.name}", metavar=param.metavar or param.type.__name__.upper(),
                             help=help_text)
    p.set_defaults(handler=lambda args: _cmd_process(processor, args))


def _frame_range(text: str) -> tuple[float, float]:
    try:
        first, last = (float(part) for part in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FIRST:LAST (e.g. 1001:1200), got {text!r}") from None
    if not (abs(first) < float("inf") and abs(last) < float("inf")):
        raise argparse.ArgumentTypeError(f"frame numbers must be finite, got {text!r}")
    if last < first:
        raise argparse.ArgumentTypeError(f"empty frame range {text!r}")
    return first, last


def _cmd_process(processor, args) -> int:
    from facedyn.errors import UsageError
    from facedyn.processors.base import Request
    from facedyn.processors.runner import execute
    from facedyn.progress import Progress

    by_name = {p.name: p for p in processor.parameters}
    given: dict = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep:
            raise UsageError(f"-p expects KEY=VALUE, got {item!r}")
        if key not in by_name:
            raise UsageError(f"{processor.name}: unknown parameter {key!r}; known: {', '.join(by_name) or 'none'}")
        given[key] = by_name[key].parse(value)
    for name, param in by_name.items():
        value = getattr(args, f"param_{name}")
        if value is not None:
            given[name] = param.parse(value)
    inputs = getattr(args, "inputs", [])
    inputs = inputs if isinstance(inputs, list) else [inputs]
    request = Request(inputs=inputs, output=args.output, frames=getattr(args, "frames", None), params=given,
                      attach=getattr(args, "attach", None))
    progress = Progress.silent() if args.quiet or args.json else Progress()
    report = execute(processor, request, progress, dry_run=args.dry_run)
    if args.json:
        print(json.dumps(report, indent=2, default=str))
    elif args.dry_run:
        print(f"{processor.name}: would write {report['output']}")
        for key, value in report["plan"].items():
            print(f"  {key}: {value}")
    elif hasattr(processor, "describe"):
        print(processor.describe(report))
    else:
        print(_describe(processor, report))
    return EXIT_OK


def _describe(processor, report: dict) -> str:
    frames = f"{report['frame_count']} frames, " if "frame_count" in report else ""
    lines = [f"{processor.name}: wrote {report['output']} ({frames}{report['seconds']['total']:.2f}s)"]
    if "root" in report:
        lines.append(f"  take root: {report['root']}")
    for stale in report.get("stale", []):
        lines.append(f"  stale now (recompute it): {stale}")
    for key, value in report["summary"].items():
        lines.append(f"  {key}: {value}")
    return "\n".join(lines)
