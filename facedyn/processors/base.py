"""The processor contract: every usdfacedyn command that makes something is a declared processor.

A processor declares
- its typed parameters (`Parameter`: type, default or required, range, choices), from which
  the CLI, `--help`, `-p key=value` and the validation of every value are generated;
- what it reads (`Reads`): a take (composed from the layers below the role it writes),
  several takes or corpora, source files, or nothing;
- what it writes (`Writes`): a layer with a role, a file (a model, an actor), or a folder;
and implements `prepare(request)`, which reads every input once and checks it, returning a
`Plan` (what `--dry-run` prints plus the arrays `run` needs), and `run(plan, progress)`,
which computes and returns the output. The runner (facedyn.processors.runner) checks paths,
writes the output atomically with provenance and attaches layers to their take root;
processors never write layers or models themselves. Third parties register processors
(layer steps, trainers, corpus builders) in the `facedyn.processors` entry-point group.
"""
from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, ClassVar, Iterable

from facedyn.errors import UsageError
from facedyn.progress import Progress


class _Required:
    def __repr__(self) -> str:
        return "required"


REQUIRED: Any = _Required()
"""The default of a parameter that must be given."""

_BOOL_WORDS = {"1": True, "true": True, "yes": True, "on": True, "0": False, "false": False, "no": False, "off": False}


@dataclass(frozen=True)
class Parameter:
    """One typed parameter; becomes `--name` (and `-p name=value`) on the command line.

    Values are checked here, where they are declared: floats must be finite, numbers must
    lie in [minimum, maximum] (and above `above`, exclusive), strings in `choices`, and
    `check` (value -> error text or None) covers what a range cannot say.
    """

    name: str
    type: type
    default: Any = REQUIRED
    help: str = ""
    choices: tuple | None = None
    minimum: float | None = None
    maximum: float | None = None
    above: float | None = None
    check: Callable[[Any], str | None] | None = None
    metavar: str | None = None

    @property
    def required(self) -> bool:
        return self.default is REQUIRED

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def parse(self, text: str) -> Any:
        """Convert a command-line string and validate it, or raise UsageError naming the flag."""
        try:
            if self.type is bool:
                value = _BOOL_WORDS[text.strip().lower()]
            elif self.type is Path:
                if not text:
                    raise ValueError(text)
                value = Path(text)
            else:
                value = self.type(text)
        except (ValueError, KeyError):
            kind = "a path" if self.type is Path else "true or false" if self.type is bool else self.type.__name__
            raise UsageError(f"{self.flag}: expected {kind}, got {text!r}") from None
        return self.validate(value)

    def validate(self, value: Any) -> Any:
        """Check a value given in Python (or parsed); return it, or raise UsageError naming the flag."""
        if value is None or value is REQUIRED:
            if self.required:
                raise UsageError(f"{self.flag} is required")
            return value
        if self.type is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if self.type is Path and isinstance(value, str):
            value = Path(value)
        if not isinstance(value, self.type) or (self.type is int and isinstance(value, bool)):
            raise UsageError(f"{self.flag}: expected {self.type.__name__}, got {value!r}")
        if isinstance(value, float) and not math.isfinite(value):
            raise UsageError(f"{self.flag}: expected a finite number, got {value!r}")
        if self.minimum is not None and value < self.minimum:
            raise UsageError(f"{self.flag}: must be at least {self.minimum:g}, got {value!r}")
        if self.maximum is not None and value > self.maximum:
            raise UsageError(f"{self.flag}: must be at most {self.maximum:g}, got {value!r}")
        if self.above is not None and value <= self.above:
            raise UsageError(f"{self.flag}: must be greater than {self.above:g}, got {value!r}")
        if self.choices is not None and value not in self.choices:
            raise UsageError(f"{self.flag}: {value!r} is not one of {', '.join(map(str, self.choices))}")
        if self.check is not None and (problem := self.check(value)):
            raise UsageError(f"{self.flag}: {problem}")
        return value


@dataclass(frozen=True)
class Reads:
    """What a processor reads from its positional arguments."""

    what: str  # "take": one take root; "takes": takes, take folders or corpus folders; "sources": files; "nothing"
    metavar: str = "TAKE"
    help: str = ""
    frame_range: bool = False  # takes --frames FIRST:LAST (every layer step does)

    @property
    def many(self) -> bool:
        return self.what in ("takes", "sources")


@dataclass(frozen=True)
class Writes:
    """What a processor writes to `-o`."""

    what: str  # "layer" (with `role`), "file" (a model, an actor asset) or "folder"
    role: str | None = None
    metavar: str = "LAYER"
    help: str = ""
    default: str | None = None  # a default output (else -o is required)
    # a folder filled one complete part at a time (a corpus's takes): a failed or interrupted run keeps the parts it
    # completed, and the next run on the folder resumes from them
    resumable: bool = False
    attach: bool = True  # a layer may be placed in a take root with --attach (False: the step makes its own root, as import)


@dataclass
class Request:
    """A processor run as asked for on the command line (or by a script)."""

    inputs: list[Path]
    output: Path
    frames: tuple[float, float] | None = None
    params: dict[str, Any] = field(default_factory=dict)
    attach: Path | None = None


@dataclass
class Plan:
    """What prepare() found: the description --dry-run prints, and what run() computes from."""

    description: dict[str, Any]
    state: Any = None


@dataclass
class LayerOutput:
    """One layer's content plus what the runner needs to write and report it."""

    layer: Any  # facedyn.usd.layers.LayerContent
    timing: Any  # facedyn.usd.timing.Timing
    inputs: list[str]
    define: bool = False
    summary: dict[str, Any] = field(default_factory=dict)
    root: Path | None = None  # a take root to create (or extend) with this layer as its base
    actor: Path | None = None  # an actor asset to record in that take root (import --actor)
    # Streamed per-frame values: consecutive LayerContents over layer.frames, computed as the
    # runner writes them (layer then holds the static values, read after the first chunk).
    chunks: Iterable[Any] | None = None


@dataclass
class FileOutput:
    """A file (a model, an actor asset) and the function that saves it atomically at a path."""

    save: Callable[[Path], Path]
    summary: dict[str, Any] = field(default_factory=dict)


@dataclass
class FolderOutput:
    """A folder the processor filled (the runner removes it again if the run fails)."""

    summary: dict[str, Any] = field(default_factory=dict)


class Processor(ABC):
    """Base class of every declared processor (layer steps, trainers, corpus builders)."""

    name: ClassVar[str]
    version: ClassVar[str] = "1"
    summary: ClassVar[str] = ""
    reads: ClassVar[Reads] = Reads("take")
    writes: ClassVar[Writes] = Writes("layer")
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    def resolve_params(self, given: dict[str, Any]) -> dict[str, Any]:
        """Defaults overlaid with `given`, every value validated; unknown names are a usage error."""
        known = {p.name: p for p in self.parameters}
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise UsageError(f"{self.name}: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(known) or 'none'}")
        resolved = {}
        for name, param in known.items():
            value = given.get(name, param.default)
            resolved[name] = param.validate(None if value is REQUIRED else value)
        return resolved

    @abstractmethod
    def prepare(self, request: Request) -> Plan:
        """Read and check every input once (nothing is written); return the plan."""

    @abstractmethod
    def run(self, plan: Plan, progress: Progress) -> LayerOutput | FileOutput | FolderOutput:
        """Compute the output from what prepare() read."""


def single_input(request: Request, what: str = "TAKE") -> Path:
    """The one positional input of a processor that reads one take."""
    if len(request.inputs) != 1:
        raise UsageError(f"give one {what}, got {len(request.inputs)}")
    return Path(request.inputs[0])


def _check_inference_device(text: str) -> str | None:
    """Where a model's network runs: numpy (on the CPU, no torch) or a torch device (check_device)."""
    return None if text == "numpy" else check_device(text)


INFERENCE_DEVICE = Parameter("device", str, "auto", "where the network runs: auto (a CUDA GPU if there is one, else numpy), "
                             "numpy (the CPU, without torch), or a torch device: cpu, cuda, cuda:N", check=_check_inference_device)


def check_device(text: str) -> str | None:
    """torch device names: auto, cpu, cuda or cuda:N, a CUDA one only where this torch has that GPU."""
    if text in ("auto", "cpu"):
        return None
    if text == "cuda" or (text.startswith("cuda:") and text[5:].isdigit()):
        from facedyn.dynamics.network import cuda_problem

        return cuda_problem(text)
    return f"expected auto, cpu, cuda or cuda:N, got {text!r}"
