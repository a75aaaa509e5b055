"""usdfacedyn: run facedyn's stage processors in batch.

    usdfacedyn list                       processors and what they do
    usdfacedyn env                        the PXR_PLUGINPATH_NAME line for usdview / DCCs
    usdfacedyn inspect TAKE               layer stack, timing, roles, provenance
    usdfacedyn validate TAKE              USD's validators plus facedyn's own
    usdfacedyn PROCESSOR INPUT... -o OUT  one subcommand per registered processor

Exit codes: 0 ok, 1 failure (bad input, failed validation), 2 usage error.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import traceback
from pathlib import Path

EXIT_OK, EXIT_FAILURE, EXIT_USAGE = 0, 1, 2


class _Parser(argparse.ArgumentParser):
    """argparse that reports usage errors as one line and exit code 2."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"{self.prog}: usage error: {message} (see --help)\n")


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    debug = "--debug" in argv
    try:
        import facedyn.usd  # noqa: F401  (registers the USD plugins; fails with a clear message if it cannot)
    except Exception as exc:
        print(f"usdfacedyn: error: {exc}", file=sys.stderr)
        return EXIT_FAILURE
    from facedyn.errors import FacedynError, UsageError

    try:
        args = build_parser(argv).parse_args(argv)
        return args.handler(args)
    except KeyboardInterrupt:
        print("usdfacedyn: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # every failure ends as one line; --debug shows the traceback
        if debug:
            traceback.print_exc()
        if isinstance(exc, UsageError):
            print(f"usdfacedyn: usage error: {exc}", file=sys.stderr)
            return EXIT_USAGE
        if isinstance(exc, FacedynError):
            print(f"usdfacedyn: error: {exc}", file=sys.stderr)
            return EXIT_FAILURE
        if isinstance(exc, OSError):
            print(f"usdfacedyn: error: {exc.filename or ''}: {exc.strerror or exc}".lstrip(": "), file=sys.stderr)
            return EXIT_FAILURE
        print(f"usdfacedyn: internal error: {type(exc).__name__}: {exc} (rerun with --debug for a traceback)", file=sys.stderr)
        return EXIT_FAILURE


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The top-level parser; only the processor named in argv is imported."""
    from facedyn.processors import registry

    parser = _Parser(prog="usdfacedyn", description=__doc__.split("\n\n")[0])
    parser.add_argument("--version", action="version", version=_version_text())
    parser.add_argument("--debug", action="store_true", help="show tracebacks for errors")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    commands.required = True

    p = commands.add_parser("list", help="list the registered processors")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=_cmd_list)

    p = commands.add_parser("env", help="print the shell line that makes usdview and DCCs load facedyn's plugins")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=_cmd_env)

    p = commands.add_parser("inspect", help="show a take's layer stack, timing, roles and provenance")
    p.add_argument("take", type=Path, metavar="TAKE")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=_cmd_inspect)

    p = commands.add_parser("validate", help="run USD's validators and facedyn's own on a take")
    p.add_argument("take", type=Path, metavar="TAKE")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=_cmd_validate)

    p = commands.add_parser("synth", help="simulate a corpus of takes with known truth (the papers' capture protocol)")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="DIR", help="corpus folder to write")
    p.add_argument("--scale", choices=("demo", "standard"), default="demo", help="protocol size (default: demo)")
    p.add_argument("--rig", type=Path, help="a UsdSkel blend-shape rig (default: the built-in face)")
    p.add_argument("--actor-seed", type=int, help="make another actor from the rig's identity modes")
    p.add_argument("--data", type=Path, help="../shared/data-like folder with Live Link curves and CMU mocap for dialog takes")
    p.add_argument("--noise", type=float, default=0.0, metavar="CM", help="Gaussian tracking noise on the captured points")
    p.add_argument("--seed", type=int, default=0, help="seed of the protocol's random choices")
    p.add_argument("--only", metavar="PATTERN", help="only takes whose name matches this glob pattern")
    p.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="takes simulated at once (default: one per core)")
    p.add_argument("--json", action="store_true", help="print the corpus index as JSON")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=_cmd_synth)

    p = commands.add_parser("train-removal", help="train the removal network F on a corpus and write a model file")
    p.add_argument("inputs", nargs="+", type=Path, metavar="CORPUS", help="corpus folders (corpus.json), take folders or stabilized takes")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="MODEL", help="model file to write (e.g. actor.removal)")
    p.add_argument("--skull", choices=("take", "truth"), default="take", help="the takes' solved skull, or a simulated corpus's true skull")
    p.add_argument("--epochs", type=int, default=250, help="training epochs (default: 250, as the paper)")
    p.add_argument("--subsample", type=float, default=1.0, help="fraction of the (frame, sample) pairs drawn each epoch")
    p.add_argument("--target", choices=("moving-average", "truth"), default="moving-average",
                   help="F's targets: the paper's moving-average offsets, or a simulated corpus's true dynamics (with --skull truth)")
    p.add_argument("--skull-features", choices=("velocity", "acceleration"), default="velocity",
                   help="F's skull input: the paper's landmark velocities over t-10..t+10 (default) or accelerations over t-30..t+10")
    _add_training_arguments(p)
    p.set_defaults(handler=_cmd_train_removal)

    p = commands.add_parser("train-synthesis", help="train the synthesis network H on a corpus and write a model file")
    p.add_argument("inputs", nargs="+", type=Path, metavar="CORPUS", help="corpus folders (corpus.json), take folders or stabilized takes")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="MODEL", help="model file to write (e.g. actor.synthesis)")
    p.add_argument("--quasistatic", required=True, metavar="MODEL|truth", help="a removal model (the paper's way) or 'truth' (a simulated corpus's true shapes)")
    p.add_argument("--skull", choices=("take", "truth"), default="take", help="the takes' solved skull, or a simulated corpus's true skull")
    p.add_argument("--epochs", type=int, default=30, help="training epochs (default: 30, as the paper)")
    p.add_argument("--skull-features", choices=("acceleration", "velocity"), default="acceleration",
                   help="H's skull input: landmark accelerations over t-30..t+10 (default, beyond the paper) or the paper's velocities over t-10..t+10")
    _add_training_arguments(p)
    p.set_defaults(handler=_cmd_train_synthesis)

    p = commands.add_parser("demo", help="run the whole pipeline on the built-in face and report errors against truth")
    p.add_argument("-o", "--output", type=Path, default=Path("demo-out"), metavar="DIR", help="output folder (default: demo-out)")
    p.add_argument("--scale", choices=("demo", "standard"), default="demo", help="corpus and training size (default: demo, a few minutes)")
    p.add_argument("--rig", type=Path, help="a UsdSkel blend-shape rig instead of the built-in face")
    p.add_argument("--data", type=Path, help="../shared/data-like folder: adds dialog takes to the corpus")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    p.set_defaults(handler=_cmd_demo)

    requested = next((a for a in argv if not a.startswith("-")), None)
    for name, entry_point in registry.available().items():
        if name == requested:
            _add_processor_parser(commands, registry.load(name))
        else:
            commands.add_parser(name, help=f"processor ({entry_point.value})")
    return parser


def _add_training_arguments(p) -> None:
    """The flags train-removal and train-synthesis share."""
    p.add_argument("--samples", type=int, default=344, help="skin samples when the takes (or the removal model) define none")
    p.add_argument("--validation", metavar="NAMES", help="comma-separated take names held out for validation (default: the last take)")
    p.add_argument("--include", metavar="PATTERN", help="only takes whose name matches this glob pattern")
    p.add_argument("--exclude", metavar="PATTERN", help="leave out takes whose name matches this glob pattern")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="auto", help="torch device: auto, cpu, cuda")
    p.add_argument("--backend", choices=("auto", "opencl", "numpy"), default="auto", help="feature and stretch kernels")
    p.add_argument("--json", action="store_true", help="print a JSON report")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)


def _add_processor_parser(commands, processor) -> None:
    p = commands.add_parser(processor.name, help=processor.summary, description=processor.summary)
    nargs = "+" if processor.many_inputs else None
    p.add_argument("inputs", nargs=nargs, type=Path, metavar=processor.input_metavar)
    p.add_argument("-o", "--output", type=Path, required=True, help="the layer to write (.usdc)")
    p.add_argument("--attach", type=Path, metavar="ROOT", help="add the output to ROOT's subLayers as the strongest layer")
    p.add_argument("--frames", type=_frame_range, metavar="FIRST:LAST", help="only these frames (inclusive time codes)")
    p.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE", help="set a processor parameter")
    p.add_argument("--dry-run", action="store_true", help="check inputs and parameters, write nothing")
    p.add_argument("--json", action="store_true", help="print a JSON report on stdout")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress output")
    p.add_argument("--debug", action="store_true", help=argparse.SUPPRESS)
    options = p.add_argument_group(f"{processor.name} parameters (also -p KEY=VALUE)")
    for param in processor.parameters:
        flag = "--" + param.name.replace("_", "-")
        help_text = f"{param.help} (default: {param.default})"
        options.add_argument(flag, dest=f"param_{param.name}", metavar=param.type.__name__.upper(), help=help_text)
    p.set_defaults(handler=lambda args: _cmd_process(processor, args))


def _frame_range(text: str) -> tuple[float, float]:
    try:
        first, last = (float(part) for part in text.split(":"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected FIRST:LAST (e.g. 1001:1200), got {text!r}") from None
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
    inputs = args.inputs if isinstance(args.inputs, list) else [args.inputs]
    request = Request(inputs=inputs, output=args.output, frames=args.frames, params=given)
    progress = Progress.silent() if args.quiet or args.json else Progress()
    report = execute(processor, request, progress, attach_to=args.attach, dry_run=args.dry_run)
    if args.json:
        print(json.dumps(report, indent=2, default=str))
    elif args.dry_run:
        print(f"{processor.name}: would write {report['output']}")
        for key, value in report["plan"].items():
            print(f"  {key}: {value}")
    else:
        print(f"{processor.name}: wrote {report['output']} ({report['frame_count']} frames, {report['seconds']['total']:.2f}s)")
        if "root" in report:
            print(f"  take root: {report['root']}")
        for key, value in report["summary"].items():
            print(f"  {key}: {value}")
    return EXIT_OK


def _cmd_list(args) -> int:
    from facedyn.processors import registry

    rows = []
    for name, entry_point in registry.available().items():
        try:
            summary = registry.load(name).summary
        except Exception as exc:  # list what is there even when one plugin is broken
            summary = f"(failed to load: {exc})"
        rows.append({"name": name, "entry_point": entry_point.value, "summary": summary})
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        width = max((len(r["name"]) for r in rows), default=0)
        for row in rows:
            print(f"{row['name']:<{width}}  {row['summary']}")
    return EXIT_OK


def _cmd_env(args) -> int:
    from facedyn.usd.plugin import export_line

    print(export_line())
    return EXIT_OK


def _cmd_inspect(args) -> int:
    from facedyn.usd.inspect import describe_take, format_description

    description = describe_take(args.take)
    print(json.dumps(description, indent=2, default=str) if args.json else format_description(description))
    return EXIT_OK


def _cmd_validate(args) -> int:
    from facedyn.usd.validate import validate_take

    findings = validate_take(args.take)
    errors = [f for f in findings if f.severity == "error"]
    if args.json:
        print(json.dumps([f.__dict__ for f in findings], indent=2))
    else:
        for finding in findings:
            print(f"{finding.severity.upper()} {finding.validator}: {finding.message}")
        print(f"{args.take}: {len(errors)} error(s), {len(findings) - len(errors)} warning(s)")
    return EXIT_FAILURE if errors else EXIT_OK


def _cmd_train_removal(args) -> int:
    from facedyn.processors.train_removal import train_removal_command

    return _report_training("train-removal", train_removal_command(args), args.json)


def _cmd_train_synthesis(args) -> int:
    from facedyn.processors.train_synthesis import train_synthesis_command

    return _report_training("train-synthesis", train_synthesis_command(args), args.json)


def _report_training(command: str, report: dict, as_json: bool) -> int:
    if as_json:
        print(json.dumps(report, indent=2, default=str))
    else:
        print(f"{command}: wrote {report['model']} ({report['takes']} takes, {report['samples']} samples, {report['seconds']['total']} s)")
        if report["validation"]:
            v = report["validation"]
            print(f"  validation RMS {v['rms_cm']:.4f} cm (zero-offset baseline {v['zero_offset_rms_cm']:.4f} cm)")
    return EXIT_OK


def _cmd_demo(args) -> int:
    from facedyn.demo import format_summary, run_demo

    summary = run_demo(args.output, args.scale, args.rig, args.data, args.json)
    print(json.dumps(summary, indent=2, default=str) if args.json else format_summary(summary))
    return EXIT_OK


def _cmd_synth(args) -> int:
    import fnmatch

    from facedyn.errors import UsageError
    from facedyn.progress import Progress
    from facedyn.sim.corpus import protocol
    from facedyn.usd.corpus import build_corpus

    rig = _load_rig(args.rig, args.actor_seed)
    specs = protocol(rig, args.scale, args.data, seed=args.seed, noise_cm=args.noise)
    if args.only:
        specs = [s for s in specs if fnmatch.fnmatch(s.name, args.only)]
        if not specs:
            raise UsageError(f"no take of the {args.scale} protocol matches {args.only!r}")
    description = {"scale": args.scale, "rig": str(args.rig or "built-in"), "actor_seed": args.actor_seed, "noise_cm": args.noise, "seed": args.seed}
    index = build_corpus(args.output, rig, specs, progress=Progress.silent() if args.json else Progress(), description=description,
                         jobs=max(1, args.jobs))
    if args.json:
        print(json.dumps(index, indent=2))
    else:
        print(f"synth: wrote {len(index['takes'])} takes ({index['frames']} frames of {index['points']} points) to {args.output}")
        print(f"  {index['simulated_frames_per_second']} frames/s simulated and written ({args.jobs} jobs); {index['seconds']['total']} s in all")
    return EXIT_OK


def _load_rig(path: Path | None, actor_seed: int | None):
    """The built-in face or a USD blend-shape rig, optionally turned into another actor."""
    if path is None:
        from facedyn.sim.default_face import default_face

        rig = default_face()
    else:
        from facedyn.usd.rig import read_blendshape_rig

        rig = read_blendshape_rig(path)
    return rig if actor_seed is None else rig.make_actor(seed=actor_seed)


def _version_text() -> str:
    import facedyn
    from facedyn.usd.plugin import usd_version

    return f"usdfacedyn {facedyn.__version__} (USD {usd_version()})"


if __name__ == "__main__":
    sys.exit(main())
