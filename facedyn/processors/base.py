"""The processor contract: what a stage processor declares and what it returns.

A processor is a small class with a name, typed parameters with defaults, and a `run`
that reads its inputs and returns a `Result` (the arrays of one layer). The runner
(facedyn.processors.runner) validates the output path, writes the layer atomically with
provenance, and attaches it to a take root; processors never write files themselves.
Third parties register their own processors in the `facedyn.processors` entry-point group.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

from facedyn.errors import UsageError
from facedyn.progress import Progress


@dataclass(frozen=True)
class Parameter:
    """One typed processor parameter; becomes `--name` and `-p name=value` on the CLI."""

    name: str
    type: type
    default: Any
    help: str
    choices: tuple | None = None

    def parse(self, text: str) -> Any:
        """Convert a command-line string, or raise UsageError naming the parameter."""
        try:
            if self.type is bool:
                lowered = text.strip().lower()
                if lowered not in ("1", "0", "true", "false", "yes", "no", "on", "off"):
                    raise ValueError(text)
                value = lowered in ("1", "true", "yes", "on")
            else:
                value = self.type(text)
        except ValueError:
            raise UsageError(f"parameter {self.name}: expected {self.type.__name__}, got {text!r}") from None
        if self.choices is not None and value not in self.choices:
            raise UsageError(f"parameter {self.name}: {value!r} is not one of {', '.join(map(str, self.choices))}")
        return value


@dataclass
class Request:
    """A processor run as asked for on the command line (or by a script)."""

    inputs: list[Path]
    output: Path
    frames: tuple[float, float] | None = None
    params: dict[str, Any] = field(default_factory=dict)


@dataclass
class Result:
    """One layer's content plus what the runner needs to write and report it."""

    layer: Any  # facedyn.usd.layers.LayerContent
    timing: Any  # facedyn.usd.timing.Timing
    inputs: list[str]
    define: bool = False
    summary: dict[str, Any] = field(default_factory=dict)
    root: Path | None = None  # a take root to create (or extend) with this layer as its base


class Processor(ABC):
    """Base class of every stage processor."""

    name: ClassVar[str]
    version: ClassVar[str] = "1"
    summary: ClassVar[str] = ""
    input_metavar: ClassVar[str] = "TAKE"
    many_inputs: ClassVar[bool] = False
    parameters: ClassVar[tuple[Parameter, ...]] = ()

    def resolve_params(self, given: dict[str, Any]) -> dict[str, Any]:
        """Defaults overlaid with `given`; unknown names are a usage error."""
        known = {p.name: p for p in self.parameters}
        unknown = sorted(set(given) - set(known))
        if unknown:
            raise UsageError(f"{self.name}: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(known) or 'none'}")
        return {name: given.get(name, p.default) for name, p in known.items()}

    @abstractmethod
    def check(self, request: Request) -> dict[str, Any]:
        """Validate the inputs without computing; return a description for --dry-run."""

    @abstractmethod
    def run(self, request: Request, progress: Progress) -> Result:
        """Compute the layer's content from the inputs."""
