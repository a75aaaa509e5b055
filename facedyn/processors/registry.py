"""Processor discovery through the `facedyn.processors` entry-point group.

Entry points are listed without importing anything; a processor's module is imported only
when the processor is asked for, so a broken third-party plugin cannot break the others.
"""
from __future__ import annotations

import functools
import sys
from importlib.metadata import EntryPoint, entry_points

from facedyn.errors import FacedynError, UsageError
from facedyn.processors.base import Processor

GROUP = "facedyn.processors"


def available() -> dict[str, EntryPoint]:
    """Registered processor names and their (not yet loaded) entry points, sorted by name."""
    return dict(_scan(tuple(sys.path)))


@functools.lru_cache(maxsize=4)
def _scan(path: tuple[str, ...]) -> tuple[tuple[str, EntryPoint], ...]:
    """One scan of the installed distributions per search path (20-40 ms each; --help asks once per processor)."""
    return tuple((ep.name, ep) for ep in sorted(entry_points(group=GROUP), key=lambda ep: ep.name))


def load(name: str) -> Processor:
    """Import and instantiate the processor registered as `name`."""
    points = available()
    if name not in points:
        raise UsageError(f"no processor named {name!r}; available: {', '.join(points) or 'none'}")
    try:
        cls = points[name].load()
    except Exception as exc:  # a third-party plugin that fails to import
        raise FacedynError(f"processor {name!r} ({points[name].value}) failed to load: {exc}") from exc
    if not (isinstance(cls, type) and issubclass(cls, Processor)):
        raise FacedynError(f"processor {name!r} ({points[name].value}) is not a facedyn Processor class")
    return cls()
