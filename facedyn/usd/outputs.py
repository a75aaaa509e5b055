"""Output paths that cannot clash with what a run reads or the root it edits.

Checked before any work, on real paths (symlinks resolved): a run may not write over any
layer of an input's stack (except the layer its own role replaces), over the root it
attaches to, or over a file that would then list itself; the root it attaches to (or an
import creates) may not be one of the data files it reads; and a layer is attached only to
the root it was read from (its provenance names that root's layers).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from pxr import Sdf

from facedyn.errors import UsageError
from facedyn.usd.layerstack import is_take_root, layer_metadata, recorded_role_name
from facedyn.usd.stackstatus import muted_assets
from facedyn.usd.stage import resolve_asset_path


@dataclass(frozen=True)
class StackFile:
    """A file of a layer stack: its real path, the role it records, and whether it only lists others."""

    path: Path
    role: str | None
    is_root: bool


def _stack_files(path: str | os.PathLike) -> list[StackFile]:
    """path and every layer it lists (subLayers, recursively, and layers muted on disk); path first."""
    files, seen, todo = [], set(), [Path(path).resolve()]
    while todo:
        current = todo.pop(0)
        if current in seen:
            continue
        seen.add(current)
        layer = None
        if current.is_file() and current.suffix.lstrip(".") and Sdf.FileFormat.FindByExtension(current.suffix.lstrip(".")):
            try:
                layer = Sdf.Layer.OpenAsAnonymous(str(current), metadataOnly=True)
            except Exception:  # an unreadable input is reported by whoever reads it
                layer = None
        if layer is None:
            files.append(StackFile(current, None, False))
            continue
        files.append(StackFile(current, recorded_role_name(layer_metadata(layer)), is_take_root(layer)))
        todo += [resolve_asset_path(a, current.parent) for a in list(layer.subLayerPaths) + muted_assets(layer)]
    return files


def check_output_paths(
    output: str | os.PathLike,
    inputs: list[str | os.PathLike],
    attach: str | os.PathLike | None = None,
    root: str | os.PathLike | None = None,
    role: str | None = None,
) -> None:
    """Raise a UsageError naming the clash when `output` (written as `role`) would overwrite what the run reads or edits.

    attach: the root the output is attached to (--attach); root: the root an import creates
    or extends (--root, or its default).
    """
    out = Path(output).resolve()
    stacks = {str(i): _stack_files(i) for i in inputs}
    for name, files in stacks.items():
        if files[0].path == out:
            raise UsageError(f"{output}: the output would overwrite the input {name}; choose another -o")
        _check_not_layer_of(output, out, name, files[1:], role)
    for target, flag in ((attach, "--attach"), (root, "--root")):
        if target is None:
            continue
        target_path = Path(target).resolve()
        if target_path == out:
            raise UsageError(f"{output}: the output is also the {flag} root; a layer cannot list itself")
        for name, files in stacks.items():
            for f in files:
                if f.path == target_path and not f.is_root:
                    raise UsageError(
                        f"{target}: {flag} names a data layer of the input {name}; attaching there would edit the input. "
                        "Give a take root (.usda) instead"
                    )
        _check_not_layer_of(output, out, str(target), _stack_files(target_path)[1:], role)
    reads_a_take = root is None  # an import (which has a root of its own) reads sources, and refuses --attach itself
    if attach is not None and reads_a_take and inputs and Path(attach).resolve() not in {Path(i).resolve() for i in inputs}:
        read = ", ".join(str(i) for i in inputs)
        raise UsageError(f"--attach {attach}: a layer goes only into the root whose layers it was computed from ({read}); "
                         f"attached to another take it would be stale there at once. Run the step on {attach} instead")


def _check_not_layer_of(output, out: Path, owner: str, files: list[StackFile], role: str | None) -> None:
    for f in files:
        if f.path == out and (role is None or f.role != role):
            what = f"its {f.role} layer" if f.role else "one of its layers"
            raise UsageError(f"{output}: the output is {what} of {owner}; writing it would replace what the run reads. Choose another -o")
