"""A package's public names, loaded from their submodules on first use (PEP 562).

An algorithm package states its public names in `__all__` without importing the modules
that define them: `import facedyn.dynamics` must not pull in PyTorch, nor
`import facedyn.stabilize` SciPy, since every command's start-up would pay for them.
"""
from __future__ import annotations

import importlib
import sys
from typing import Callable


def lazy_exports(package: str, public: dict[str, str]) -> tuple[list[str], Callable[[str], object]]:
    """(`__all__`, the module's `__getattr__`) for `package`, whose public `name` lives in `package.public[name]`."""

    def __getattr__(name: str):
        if name not in public:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{public[name]}"), name)
        setattr(sys.modules[package], name, value)  # later look-ups find it without this hook
        return value

    return sorted(public), __getattr__
