"""What a batch will do: the captures, their take names, and each step's command line.

The steps are processors, and their command lines are built from the processors'
declarations (facedyn.processors.base): each step's order is its role's rank, its layer is
named after its role (the role table's file names), the capture goes to the step that reads
sources, and every flag it is given is one it declares: batch's own options are steps'
parameters (`STEP_OPTIONS`), each given to the step that writes a role, so a processor's
flag renamed or dropped is an error here, not a batch that runs with the wrong flags.
"""
from __future__ import annotations

import glob
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import TYPE_CHECKING

from facedyn.errors import FacedynError, UsageError
from facedyn.io.errors import InputError
from facedyn.io.files import check_not_special, read_lines
from facedyn.performance import QUASISTATIC, STABILIZED, SYNTHESIZED, TAKE_ROOT_FILE, role
from facedyn.processors.commandline import ATTACH_FLAG, OUTPUT_FLAG, QUIET_FLAG

if TYPE_CHECKING:
    from facedyn.processors.base import Parameter

STEPS = ("import", "stabilize", "remove", "synthesize", "preview")  # the layer processors a capture can go through, in role rank order
SHOT_LIST_SUFFIXES = (".txt", ".list")


@dataclass(frozen=True)
class StepOption:
    """A batch option that is one step's declared parameter: given as `parameter` to the step that writes `role`.

    Declared here, not read from the processors, because `usdfacedyn`'s parser is built on
    every start and must not import the processors' modules."""

    field: str  # its Models field
    flag: str  # batch's flag
    role: str  # the role the step it is given to writes
    parameter: str  # that step's parameter
    metavar: str
    help: str
    file: bool = True  # its value is a path (else a name, or a path when such a file exists: a skull motion)
    needs: str = ""  # what the step lacks when its parameter is required and the option is not given
    labels: bool = False  # its value names the variant the step writes (synthesized.hop.usdc)
    shipped: bool = False  # its value may name a model shipped with facedyn (facedyn.models: default)
    alias: str | None = None  # the flag's deprecated old spelling


STEP_OPTIONS = (
    StepOption("actor", "--actor", STABILIZED, "actor", "A", "an actor asset (usdfacedyn actor): stabilize puts every take in its skull frame"),
    StepOption("removal", "--removal-model", QUASISTATIC, "model", "F", "removal model for the remove step (its --model): network F, "
               "an actor's linear response, a blend, or `default` (the shipped person-independent one)", needs="a removal model", shipped=True,
               alias="--model"),
    StepOption("synthesis", "--synthesis-model", SYNTHESIZED, "model", "H", "synthesis model for the synthesize step", needs="a synthesis model"),
    StepOption("skull_motion", "--skull-motion", SYNTHESIZED, "skull_motion", "M",
               "new skull motion for synthesize: BVH, stabilized take, or walk|run|hop|still|platform:9hz", file=False, labels=True),
)


@dataclass(frozen=True)
class Models:
    """What the steps read besides the take: F, H and the new skull motion (STEP_OPTIONS say which step reads which)."""

    removal: Path | None = None
    synthesis: Path | None = None
    skull_motion: str | None = None  # a BVH file or stabilized take, or a procedural motion (walk, platform:9hz)
    actor: Path | None = None  # an actor asset: stabilize puts every take in its skull frame


@dataclass(frozen=True)
class StepPlan:
    """One step of one take: the command line that runs it and what it writes."""

    take: str
    step: str
    folder: Path  # OUTDIR/<take>
    output: Path
    argv: tuple[str, ...]  # usdfacedyn's arguments
    inputs: tuple[Path, ...]  # files beside the take whose checksums say whether the step is current
    reads_capture: bool = False  # the step reads the capture (inputs[0]) and makes the take root

    @property
    def root(self) -> Path:
        return self.folder / TAKE_ROOT_FILE


@lru_cache(maxsize=None)
def declaration(step: str):
    """The processor that runs `step` (loaded from the registry: its module only, no heavy library)."""
    from facedyn.processors import registry

    processor = registry.load(step)
    if processor.writes.what != "layer" or processor.writes.role is None:
        raise FacedynError(f"batch step {step!r}: the processor writes {processor.writes.what}, a batch step writes a layer of a role")
    return processor


def step_order(steps: tuple[str, ...]) -> tuple[str, ...]:
    """`steps` in pipeline order: by the rank of the role each step's processor writes."""
    return tuple(sorted(steps, key=lambda step: role(declaration(step).writes.role).rank))


def flag(step: str, parameter: str) -> str:
    """The command-line flag of one of the step's declared parameters; a FacedynError if the processor declares none."""
    declared = {p.name: p for p in declaration(step).parameters}
    if parameter not in declared:
        raise FacedynError(f"batch step {step!r}: the {step} processor declares no {parameter!r} parameter")
    return declared[parameter].flag


def layer_name(step: str, label: str = "") -> str:
    """The file a step's layer is written to: the role table's file for the role its processor writes."""
    return role(declaration(step).writes.role).layer_file(label)


def options_of(step: str) -> tuple[tuple[StepOption, Parameter], ...]:
    """(option, the step's declared parameter it is given as) for each batch option the step takes."""
    processor = declaration(step)
    declared = {p.name: p for p in processor.parameters}
    options = tuple(option for option in STEP_OPTIONS if option.role == processor.writes.role)
    for option in options:
        flag(step, option.parameter)  # a FacedynError if the processor no longer declares it
    return tuple((option, declared[option.parameter]) for option in options)


def parse_steps(text: str) -> tuple[str, ...]:
    """'import,stabilize' -> the steps, checked and in pipeline order."""
    steps = tuple(s.strip() for s in text.split(",") if s.strip())
    unknown = [s for s in steps if s not in STEPS]
    if unknown or not steps:
        raise UsageError(f"--steps: unknown step(s) {unknown or [text]}; choose from {','.join(STEPS)}")
    if len(set(steps)) != len(steps) or steps != step_order(steps):
        raise UsageError(f"--steps: give each step once, in pipeline order ({','.join(STEPS)}), got {text!r}")
    return steps


def find_captures(items: list[str]) -> list[Path]:
    """Mesh caches from paths, glob patterns and shot lists (one path per line, '#' comments,
    relative to the list's folder)."""
    captures: list[Path] = []
    for item in items:
        if glob.has_magic(item):
            found = sorted(glob.glob(item))
            if not found:
                raise UsageError(f"{item}: the pattern matches no file")
            captures += [Path(p) for p in found]
        elif Path(item).suffix in SHOT_LIST_SUFFIXES:
            listing = Path(item)
            try:
                lines = read_lines(listing)
            except InputError as exc:
                raise UsageError(f"cannot read the shot list {exc}") from None
            captures += [listing.parent / line.strip() for line in lines if line.strip() and not line.lstrip().startswith("#")]
        else:
            captures.append(Path(item))
    if not captures:
        raise UsageError("no capture to process")
    for capture in captures:
        check_not_special(capture)
    return [c.absolute() for c in captures]


def take_names(captures: list[Path]) -> list[str]:
    """A capture's file stem names its take; stems that repeat get their folder's name in front."""
    stems = [c.name.split(".")[0] for c in captures]
    names = [f"{c.parent.name}_{s}" if stems.count(s) > 1 else s for c, s in zip(captures, stems)]
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise UsageError(f"captures give the same take name {repeated}; rename them or run them in separate batches")
    return names


def plan_take(name: str, capture: Path, output: Path, steps: tuple[str, ...], models: Models) -> list[StepPlan]:
    """The take's steps in order."""
    folder = Path(output).absolute() / name
    root = str(folder / TAKE_ROOT_FILE)
    plans = []
    for step in steps:
        processor = declaration(step)
        extra: list[str] = []
        inputs: list[Path] = []
        label = ""
        for option, parameter in options_of(step):
            value = getattr(models, option.field)
            if value is None or value == "":
                continue
            extra += [parameter.flag, str(value)]
            if parameter.type is Path or Path(value).is_file():  # a file the step reads: its checksum says whether it is current
                inputs.append(Path(value))
            if option.labels:
                label = motion_label(value)
        reads_capture = processor.reads.what == "sources"  # (import) it makes the take root the later steps attach to
        source = str(capture) if reads_capture else root
        if reads_capture:
            inputs.insert(0, capture)
        out = folder / layer_name(step, label)
        attach = [ATTACH_FLAG, root] if processor.writes.attach else []
        argv = (step, source, *extra, OUTPUT_FLAG, str(out), *attach, QUIET_FLAG)
        plans.append(StepPlan(name, step, folder, out, argv, tuple(Path(p).absolute() for p in inputs), reads_capture))
    return plans


def motion_label(skull_motion: str | None) -> str:
    """'walk.bvh' -> 'walk', 'platform:9hz' -> 'platform9hz', none (the take's own) -> ''."""
    if not skull_motion:
        return ""
    label = Path(skull_motion).stem if Path(skull_motion).suffix else skull_motion
    return "".join(ch for ch in label if ch.isalnum() or ch in "_-")


def plan_batch(captures: list[str], output: Path, steps: tuple[str, ...], models: Models) -> list[list[StepPlan]]:
    """Every take's steps; the models the steps need must be given."""
    for option in STEP_OPTIONS:
        if getattr(models, option.field) is not None:
            check_not_special(getattr(models, option.field), option.flag)
    for step in steps:
        for option, parameter in options_of(step):
            if parameter.required and getattr(models, option.field) is None:
                raise UsageError(f"the {step} step needs {option.needs} ({option.flag})")
    found = find_captures(captures)
    return [plan_take(name, capture, output, steps, models) for name, capture in zip(take_names(found), found)]
