"""What a batch will do: the captures, their take names, and each step's command line.

The steps are processors, and their command lines are built from the processors'
declarations (facedyn.processors.base): each step's order is its role's rank, its layer is
named after its role, and every flag it is given is one it declares, so a processor's flag
renamed or dropped is an error here, not a batch that runs with the wrong flags.
"""
from __future__ import annotations

import glob
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

from facedyn.errors import FacedynError, UsageError
from facedyn.io.errors import InputError
from facedyn.io.files import check_not_special, read_lines
from facedyn.performance import CAPTURED, PREVIEW, SYNTHESIZED, role

STEPS = ("import", "stabilize", "remove", "synthesize", "preview")  # the layer processors a capture goes through
SHOT_LIST_SUFFIXES = (".txt", ".list")
LAYER_NAMES = {CAPTURED: "capture.usdc", PREVIEW: "take.preview.usdc"}  # else <role>.usdc (a variant: <role>.<label>usdc)


@dataclass(frozen=True)
class Models:
    """What the steps read besides the take: F, H and the new skull motion."""

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

    @property
    def root(self) -> Path:
        return self.folder / "take.usda"


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
    """The file a step's layer is written to: named after the role its processor writes."""
    written = declaration(step).writes.role
    return LAYER_NAMES.get(written) or f"{written}.{label}usdc"


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
    root = str(folder / "take.usda")
    plans = []
    for step in steps:
        extra: list[str] = []
        inputs: list[Path] = []
        writes = declaration(step).writes
        attach = ["--attach", root] if writes.attach else []  # import makes the take root the later steps attach to
        out, source = folder / layer_name(step, motion_label(models.skull_motion) if writes.role == SYNTHESIZED else ""), root
        if writes.role == CAPTURED:  # the step that reads the capture
            source, inputs = str(capture), [capture]
        elif step == "stabilize" and models.actor is not None:
            extra, inputs = [flag(step, "actor"), str(models.actor)], [models.actor]
        elif step == "remove":
            extra, inputs = [flag(step, "model"), str(models.removal)], [models.removal]
        elif step == "synthesize":
            extra, inputs = [flag(step, "model"), str(models.synthesis)], [models.synthesis]
            if models.skull_motion:
                extra += [flag(step, "skull_motion"), models.skull_motion]
                if Path(models.skull_motion).is_file():
                    inputs.append(Path(models.skull_motion))
        argv = (step, source, *extra, "-o", str(out), *attach, "-q")
        plans.append(StepPlan(name, step, folder, out, argv, tuple(Path(p).absolute() for p in inputs)))
    return plans


def motion_label(skull_motion: str | None) -> str:
    """'walk.bvh' -> 'walk.', 'platform:9hz' -> 'platform9hz.', none (the take's own) -> ''."""
    if not skull_motion:
        return ""
    label = Path(skull_motion).stem if Path(skull_motion).suffix else skull_motion
    return "".join(ch for ch in label if ch.isalnum() or ch in "_-") + "."


def plan_batch(captures: list[str], output: Path, steps: tuple[str, ...], models: Models) -> list[list[StepPlan]]:
    """Every take's steps; the models the steps need must be given."""
    for name, path in (("--removal-model", models.removal), ("--synthesis-model", models.synthesis), ("--actor", models.actor),
                       ("--skull-motion", models.skull_motion)):
        if path is not None:
            check_not_special(path, name)
    if "remove" in steps and models.removal is None:
        raise UsageError("the remove step needs a removal model (--removal-model)")
    if "synthesize" in steps and models.synthesis is None:
        raise UsageError("the synthesize step needs a synthesis model (--synthesis-model)")
    found = find_captures(captures)
    return [plan_take(name, capture, output, steps, models) for name, capture in zip(take_names(found), found)]
