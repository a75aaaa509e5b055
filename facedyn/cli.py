"""usdfacedyn: run facedyn's declared processors, and look at what they made.

    usdfacedyn PROCESSOR INPUT... -o OUT  one subcommand per registered processor (import,
                                          stabilize, remove, synthesize, retarget, preview,
                                          synth, train-removal, train-synthesis, demo, ...)
    usdfacedyn list                       every command and what it does
    usdfacedyn inspect TAKE|MODEL         layer stack, timing, roles, staleness, provenance
    usdfacedyn validate TAKE              USD's validators plus facedyn's own
    usdfacedyn layers TAKE                list, mute, unmute, detach or reorder a take's layers
    usdfacedyn batch CAPTURES... -o DIR   import ... preview over many captures on Dask
    usdfacedyn env                        the PXR_PLUGINPATH_NAME line for usdview / DCCs

Every processor's flags are generated from its declaration (facedyn.processors.base); the
commands that look at results (list, env, inspect, validate, layers) and batch are declared
in TOOLS below, so `list` shows every command.
Exit codes: 0 ok, 1 failure (bad input, failed validation), 2 usage error.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from facedyn.processors.commandline import EXIT_FAILURE, EXIT_OK, Parser, add_processor_parser, common_flags, run_guarded


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else [str(a) for a in argv]
    return run_guarded(argv, lambda: build_parser(argv))


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The top-level parser. A processor's module is imported only when asked for, or for --help."""
    from facedyn.processors import registry

    parser = Parser(prog="usdfacedyn", description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter,
                     epilog="Run `usdfacedyn COMMAND --help` for a command's flags. Exit codes: 0 ok, 1 failure, 2 usage error.")
    parser.add_argument("--version", action="version", version=_version_text())
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    commands.required = True
    requested = next((a for a in argv if not a.startswith("-")), None)
    # Summaries import every processor's module: only a top-level --help (or no arguments) lists them.
    wants_help = not argv or (requested is None and any(a in ("-h", "--help") for a in argv))
    for name in registry.available():
        if name == requested:
            add_processor_parser(commands, registry.load(name))
        else:
            commands.add_parser(name, help=_summary(name) if wants_help else name)
    _add_tools(commands)
    return parser


def _summary(name: str) -> str:
    from facedyn.processors import registry

    try:
        return registry.load(name).summary
    except Exception as exc:  # list what is there even when one plugin is broken
        return f"(failed to load: {exc})"


def _tool(commands, name: str, help_text: str, handler, operand: tuple[str, str] | None = None, json_help: str | None = None):
    """A look-at-results command: an optional path operand, --json when it can print JSON, --debug."""
    p = commands.add_parser(name, help=help_text)
    if operand is not None:
        p.add_argument(operand[0], type=Path, metavar=operand[1])
    if json_help is None:
        p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    else:
        common_flags(p, json_help)
    # Their handlers import facedyn.usd's modules (which register the plugins) only where they read USD.
    p.set_defaults(handler=handler, uses_usd=False)
    return p


@dataclass(frozen=True)
class Tool:
    """A command that is not a processor (it looks at what processors made, edits a take's stack, or runs
    processors in bulk), declared as processors are: its name, what it does, and how its arguments are added."""

    name: str
    summary: str
    add: Callable  # (commands, tool) -> the command's parser, its handler set


def _add_tools(commands) -> None:
    for tool in TOOLS:
        tool.add(commands, tool)


def _add_batch(commands, tool: Tool):
    from facedyn.batch.command import add_batch_arguments, run_batch

    p = commands.add_parser(tool.name, help=tool.summary)
    add_batch_arguments(p)
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=run_batch)
    return p


def _add_layers(commands, tool: Tool):
    p = commands.add_parser(tool.name, help=tool.summary,
                            description="Edits the take root atomically under its lock; the layer files themselves are never touched.")
    p.add_argument("take", type=Path, metavar="TAKE")
    action = p.add_mutually_exclusive_group()
    action.add_argument("--mute", metavar="LAYER", help="take LAYER out of the stack (remembered, so --unmute puts it back)")
    action.add_argument("--unmute", metavar="LAYER", help="put a muted LAYER back at its role's position")
    action.add_argument("--detach", metavar="LAYER", help="remove LAYER from the stack for good (the file stays)")
    action.add_argument("--move", metavar="LAYER", help="reorder LAYER among the layers of its role (with --above or --below)")
    p.add_argument("--above", metavar="OTHER", help="with --move: place LAYER just above OTHER")
    p.add_argument("--below", metavar="OTHER", help="with --move: place LAYER just below OTHER")
    common_flags(p, "print the stack as JSON")
    p.set_defaults(handler=_cmd_layers)
    return p


def _cmd_list(args) -> int:
    from facedyn.processors import registry

    rows = []
    for name, entry_point in registry.available().items():
        try:
            processor = registry.load(name)
            summary, writes = processor.summary, processor.writes.what + (f" ({processor.writes.role})" if processor.writes.role else "")
        except Exception as exc:  # list what is there even when one plugin is broken
            summary, writes = f"(failed to load: {exc})", "?"
        rows.append({"name": name, "kind": "processor", "entry_point": entry_point.value, "writes": writes, "summary": summary})
    rows += [{"name": tool.name, "kind": "tool", "entry_point": "facedyn.cli", "writes": "nothing",
              "summary": tool.summary} for tool in TOOLS if tool.name not in registry.available()]
    rows.sort(key=lambda row: row["name"])
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        width = max((len(r["name"]) for r in rows), default=0)
        for row in rows:
            print(f"{row['name']:<{width}}  {row['summary']}")
    return EXIT_OK


def _cmd_env(args) -> int:
    from facedyn.kernels.runtime import backend_report
    from facedyn.usd.plugin import export_line

    print(export_line())
    report = backend_report()
    print("# kernel backend: " + json.dumps(report, default=str))
    return EXIT_OK


def _cmd_inspect(args) -> int:
    from facedyn.io.files import check_not_special

    from facedyn.models import SHIPPED, resolve_model

    check_not_special(args.path)
    path = resolve_model(args.path, "inspect") if str(args.path) in SHIPPED else args.path
    if path.is_file() and not path.suffix.lower().startswith(".usd"):
        from facedyn.dynamics.model_text import format_model_description
        from facedyn.dynamics.modelfile import describe_model

        model = describe_model(path)
        print(json.dumps(model, indent=2, default=str) if args.json else format_model_description(model))
        return EXIT_OK
    from facedyn.usd.inspect import describe_take, format_description
    from facedyn.usd.errors import TakeError
    from facedyn.usd.stackstatus import check_not_self_listing

    if path.is_file():
        with contextlib.suppress(TakeError):  # an unreadable take is named by describe_take
            check_not_self_listing(path)
    description = describe_take(args.path)
    print(json.dumps(description, indent=2, default=str) if args.json else format_description(description))
    return EXIT_OK


def _cmd_layers(args) -> int:
    from facedyn.errors import UsageError
    from facedyn.io.files import check_not_special
    from facedyn.usd import rootedit
    from facedyn.usd.stackstatus import check_not_self_listing, check_take_root, format_layers, stack_status

    check_not_special(args.take)
    check_take_root(args.take)
    detaching_itself = args.detach is not None and args.take.resolve() in (Path(args.detach).resolve(), (args.take.parent / args.detach).resolve())
    if not detaching_itself:
        check_not_self_listing(args.take)
    if (args.above or args.below) and not args.move:
        raise UsageError("--above/--below go with --move LAYER")
    if args.move and bool(args.above) == bool(args.below):
        raise UsageError("--move LAYER needs one of --above OTHER or --below OTHER")
    if args.mute:
        rootedit.mute(args.take, args.mute)
    elif args.unmute:
        rootedit.unmute(args.take, args.unmute)
    elif args.detach:
        rootedit.detach(args.take, args.detach)
    elif args.move:
        rootedit.move(args.take, args.move, above=args.above, below=args.below)
    statuses = stack_status(args.take)
    print(json.dumps([status.as_dict() for status in statuses], indent=2, default=str) if args.json else format_layers(statuses))
    return EXIT_OK


def _cmd_validate(args) -> int:
    from facedyn.io.files import check_not_special
    from facedyn.usd.validate import validate_take

    check_not_special(args.take)
    findings = validate_take(args.take)
    errors = [f for f in findings if f.severity == "error"]
    if args.json:
        print(json.dumps([f.__dict__ for f in findings], indent=2))
    else:
        for finding in findings:
            print(f"{finding.severity.upper()} {finding.validator}: {finding.message}")
        print(f"{args.take}: {len(errors)} error(s), {len(findings) - len(errors)} warning(s)")
    return EXIT_FAILURE if errors else EXIT_OK


TOOLS = (
    Tool("list", "list every command: the registered processors and these tools",
         lambda commands, tool: _tool(commands, tool.name, tool.summary, _cmd_list, json_help="print JSON")),
    Tool("env", "print the shell lines that make usdview and DCCs load facedyn's plugins",
         lambda commands, tool: _tool(commands, tool.name, tool.summary, _cmd_env)),
    Tool("inspect", "show a take's layer stack, roles, staleness and provenance, or a model file's metadata",
         lambda commands, tool: _tool(commands, tool.name, tool.summary, _cmd_inspect, operand=("path", "TAKE|LAYER|MODEL"),
                                      json_help="print JSON")),
    Tool("validate", "run USD's validators and facedyn's own on a take",
         lambda commands, tool: _tool(commands, tool.name, tool.summary, _cmd_validate, operand=("take", "TAKE"),
                                      json_help="print the findings as JSON")),
    Tool("layers", "list a take's layers (roles, staleness), or mute, unmute, detach or reorder one on disk",
         _add_layers),
    Tool("batch", "run a pipeline of steps over many captures on a Dask cluster (local by default)", _add_batch),
)
"""The commands that are not processors, each declared once: `list` and `--help` show them beside the processors."""


def _version_text() -> str:
    """facedyn's and USD's versions; USD's from its package metadata where installed as usd-core, so
    --version does not load USD."""
    from importlib import metadata

    import facedyn

    try:
        major, minor = metadata.version("usd-core").split(".")[:2]  # 24.8 is USD 24.08
        usd = f"{int(major)}.{int(minor):02d}"
    except (metadata.PackageNotFoundError, ValueError):  # a USD built from source: ask it
        from facedyn.usd.plugin import usd_version

        usd = usd_version()
    return f"usdfacedyn {facedyn.__version__} (USD {usd})"


if __name__ == "__main__":
    sys.exit(main())
