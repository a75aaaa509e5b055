"""Models shipped with facedyn, by name: `remove --model default` reads the installed file.

`default` is a person-independent removal model (facedyn.dynamics.portable) for an actor with
neither rig nor session, trained on simulated faces by `python -m facedyn.sim.default_model`
(which writes it here). A name is only read as a shipped model when no file of that name
exists, so a model file called `default` in the working folder still wins.
"""
from __future__ import annotations

from pathlib import Path

from facedyn.errors import UsageError

SHIPPED = {"default": "default.removal"}
REBUILD = "python -m facedyn.sim.default_model -o {path}"


def shipped_path(name: str) -> Path:
    """Where the shipped model `name` is installed (a key of SHIPPED)."""
    return Path(__file__).resolve().with_name(SHIPPED[name])


def resolve_model(value, flag: str = "model") -> Path:
    """The model file `value` names: a shipped model's installed file for its name, else the path itself.

    A missing file whose name looks like a name (no folder, no suffix) is a UsageError that
    lists the shipped names, rather than the reader's "cannot read" later.
    """
    path = Path(value)
    text = str(value)
    if path.exists():
        return path
    if text in SHIPPED:
        installed = shipped_path(text)
        if not installed.is_file():
            raise UsageError(f"--{flag} {text}: the shipped model {installed} is not installed; build it with "
                             + REBUILD.format(path=installed))
        return installed
    if path.parent == Path(".") and not path.suffix:
        raise UsageError(f"--{flag} {text}: no such model file, and no shipped model of that name (shipped: {', '.join(SHIPPED)})")
    return path
