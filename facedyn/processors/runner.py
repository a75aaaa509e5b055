"""Running a processor: parameter and path checks, prepare once, run, write atomically.

What happens to the output depends only on what the processor declares it writes:
- a layer is written with its role and provenance and, with `--attach` (or an import's
  root), placed in the take root by role, under the root's lock;
- a file (a model, an actor asset) is saved atomically by the function the processor returns;
- a folder is removed again when the run fails and the folder did not exist before, unless
  the processor declares it resumable and it holds parts the run completed (kept for the next run).
Missing folders of the output are created (and removed again if the run fails).
"""
from __future__ import annotations

import os
import shutil
import time
from pathlib import Path
from typing import Any

import facedyn
from facedyn.errors import UsageError
from facedyn.processors.base import FileOutput, FolderOutput, LayerOutput, Processor, Request
from facedyn.progress import Progress


def execute(processor: Processor, request: Request, progress: Progress, dry_run: bool = False) -> dict[str, Any]:
    """Run `processor` for `request`; return a JSON-able report of what was (or would be) written."""
    request.params = processor.resolve_params(request.params)
    request.inputs = [Path(p) for p in request.inputs]
    request.output = Path(request.output)
    _check_paths(processor, request)
    report: dict[str, Any] = {
        "processor": processor.name,
        "inputs": [str(p) for p in request.inputs],
        "output": str(request.output),
        "parameters": {k: _plain(v) for k, v in request.params.items()},
    }
    if processor.writes.what == "layer":
        report["frames"] = list(request.frames) if request.frames else None
    started = time.perf_counter()
    plan = processor.prepare(request)
    report["plan"] = plan.description
    if dry_run:
        report["dry_run"] = True
        return report
    writes = processor.writes.what
    created_folder = writes == "folder" and not processor.writes.resumable and not request.output.exists()
    made = _make_folders(request.output.parent)
    try:
        output = processor.run(plan, progress)
        computed = time.perf_counter() - started
        if isinstance(output, LayerOutput):
            report.update(_write_layer(processor, request, output))
            if output.chunks is not None:  # streamed: computed while written
                computed = time.perf_counter() - started
        elif isinstance(output, FileOutput):
            report["output"] = str(output.save(request.output))
        elif not isinstance(output, FolderOutput):
            raise TypeError(f"{processor.name}.run returned {type(output).__name__}, not a declared output")
    except BaseException:
        kept = processor.writes.resumable and request.output.is_dir() and any(request.output.iterdir())
        if created_folder and request.output.is_dir() and not kept:
            shutil.rmtree(request.output, ignore_errors=True)
        for folder in reversed(made):  # the output's missing folders, made for this run
            if folder.is_dir() and not any(folder.iterdir()):
                folder.rmdir()
        raise
    report["summary"] = output.summary
    report["seconds"] = {"compute": round(computed, 3), "total": round(time.perf_counter() - started, 3)}
    return report


def _make_folders(folder: Path) -> list[Path]:
    """Create an output's missing folders (outermost first), as `mkdir -p` would; return the ones made."""
    from facedyn.errors import FacedynError

    missing = [p for p in [folder, *folder.parents] if not p.exists()][::-1]
    for path in missing:
        try:
            path.mkdir()
        except OSError as exc:
            raise FacedynError(f"{folder}: cannot create the output folder ({exc.strerror})") from None
    return missing


def _check_paths(processor: Processor, request: Request) -> None:
    """Refuse outputs that would overwrite an input, or land where nothing can be written."""
    _check_names(processor, request)
    output = request.output.resolve()
    for path in request.inputs:
        if Path(path).resolve() == output:
            raise UsageError(f"{request.output}: the output would overwrite an input; choose another -o")
    writes = processor.writes.what
    if writes == "layer":
        from facedyn.usd.outputs import check_output_paths

        check_output_paths(request.output, request.inputs, attach=request.attach,
                           root=_import_root(processor, request), role=processor.writes.role)
    elif request.output.is_dir() and writes == "file":
        raise UsageError(f"{request.output}: is a folder; -o names the file to write")
    elif request.output.exists() and writes == "folder" and not request.output.is_dir():
        raise UsageError(f"{request.output}: is a file; -o names the folder to write")
    if request.attach is not None and writes != "layer":
        raise UsageError(f"{processor.name} writes a {writes}, which cannot be attached to a take")
    if request.attach is not None and not processor.writes.attach:
        raise UsageError(f"{processor.name} creates or extends its own take root (it takes no --attach)")
    if processor.reads.what == "take":
        _check_roots_read(request.inputs)
        if writes == "layer" and processor.writes.role:
            _check_fresh_below(request.inputs, processor.writes.role)


def _check_fresh_below(inputs: list[Path], role_name: str) -> None:
    """Refuse to compute over a stale layer: the result would be fresh over a layer that no longer matches the capture."""
    from facedyn.processors import registry
    from facedyn.usd.errors import TakeError
    from facedyn.usd.layerstack import is_take_root
    from facedyn.usd.stackstatus import needs_message, open_root, stale_below

    for path in inputs:
        try:
            if not path.is_file() or not is_take_root(open_root(path)):
                continue
        except TakeError:
            continue  # an unreadable take is reported by its reader
        for status in stale_below(path, role_name):
            why = "it is missing" if status.state == "missing" else (status.reason or needs_message(status))
            fix = (f"re-run `usdfacedyn {status.processor}` on {path} first" if status.processor in registry.available()
                   else f"recompute it (its writer: {status.processor or 'unknown'}) or detach it from {path}")
            raise TakeError(f"{path}: the layer {status.asset} it would read is {status.state}: {why}. To bring it up to date, {fix}")


def _check_roots_read(inputs: list[Path]) -> None:
    """Refuse a take root that lists itself (USD only warns, and composes the rest as if it did not)."""
    from facedyn.usd.errors import TakeError
    from facedyn.usd.stackstatus import check_not_self_listing

    for path in inputs:
        try:
            if path.is_file():
                check_not_self_listing(path)
        except TakeError:
            continue  # an unreadable take is reported by its reader


LAYER_SUFFIXES = (".usd", ".usda", ".usdc")  # what a take and its layers can be written as (not .usdz packages)


def _check_names(processor: Processor, request: Request) -> None:
    """Paths a user can get wrong before any file is read: symlink loops, and take or layer names that are no USD layer."""
    from facedyn.errors import FacedynError

    named = [*request.inputs, request.output] + ([request.attach] if request.attach is not None else [])
    _check_not_special(processor, request)
    for path in named:
        try:
            path.resolve()
        except (RuntimeError, OSError):
            raise FacedynError(f"{path}: a loop of symbolic links, not a file") from None
        if not utf8_path(path):
            raise FacedynError(f"{path}: the path is not valid UTF-8, which USD needs for file names; rename it")
    if processor.reads.what == "take":
        for path in request.inputs:
            if path.suffix.lower() not in (*LAYER_SUFFIXES, ".usdz"):
                raise UsageError(f"{path}: not a take (expected a .usda/.usdc/.usd take root; `usdfacedyn import` makes one)")
    if processor.writes.what == "layer":
        for path, flag in ((request.output, "-o"), (request.attach, "--attach")):
            if path is not None and path.suffix.lower() not in LAYER_SUFFIXES:
                raise UsageError(f"{flag} {path}: a layer is written as .usdc (data) or .usda (roots), not "
                                 f"{path.suffix or 'a name without extension'}")


def _check_not_special(processor: Processor, request: Request) -> None:
    """Every path on the command line (operands, -o, --attach, path-valued flags) names a file or folder, not a FIFO or device.

    Checked on the path's status only, before any reader opens it: a FIFO would block the
    reader forever and a device would feed it endlessly. A string flag (e.g. a skull motion
    that is a BVH file or a motion's name) is checked when it names something that exists.
    """
    from facedyn.io.files import check_not_special

    for path in request.inputs:
        check_not_special(path)
    check_not_special(request.output, "-o")
    if request.attach is not None:
        check_not_special(request.attach, "--attach")
    for param in processor.parameters:
        value = request.params.get(param.name)
        if isinstance(value, (str, Path)) and str(value) and (param.type is Path or os.path.lexists(value)):
            check_not_special(value, param.flag)


def utf8_path(path: Path) -> bool:
    """Whether a path (as the OS gave it) can be handed to USD, which takes UTF-8 names."""
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def _import_root(processor: Processor, request: Request) -> Path | None:
    root = getattr(processor, "take_root", None)
    return root(request) if root else None


def _write_layer(processor: Processor, request: Request, output: LayerOutput) -> dict[str, Any]:
    from facedyn.errors import UsageError
    from facedyn.usd import layers, schema
    from facedyn.usd.rootedit import attach_written_layer, remove_created_root
    from facedyn.usd.stackstatus import covers_take

    frames = output.layer.frames
    first, last = float(frames[0]), float(frames[-1])
    root = output.root or request.attach
    parameters, files = _recorded_parameters(processor, request, root)
    provenance = schema.Provenance(
        processor=processor.name,
        version=f"facedyn {facedyn.__version__}, {processor.name} {processor.version}",
        parameters=parameters,
        frame_range=(first, last),
        inputs=_with_files(output.inputs, files, request.output),
        role=processor.writes.role,
    )

    def write():
        layers.write_layer(request.output, output.layer, output.timing, provenance, define=output.define, chunks=output.chunks)

    report: dict[str, Any] = {"frame_count": int(len(frames)), "frame_range": [first, last]}
    if root is None:
        write()
        return report
    root = Path(root)
    if root.exists() and not covers_take(root, (first, last)):
        raise UsageError(f"--frames {first:g}:{last:g} covers only part of {root}'s frames; attached, the layer would hold its "
                         "last sample over the rest of the take. Process the whole take, or leave out --attach")
    root_existed = root.exists()
    try:
        placed = attach_written_layer(root, request.output, processor.writes.role, write,
                                      create_with=output.timing if output.define else None, actor=output.actor)
    except BaseException:
        if not root_existed:
            remove_created_root(root, request.output)
        raise
    report.update(root=str(root), sublayers=placed.sublayers, stale=placed.stale)
    return report


def _recorded_parameters(processor: Processor, request: Request, root: Path | None) -> tuple[dict[str, Any], list[Path]]:
    """The parameters as a layer records them, and the files they name that the run reads.

    A path parameter (a model, an actor) is recorded relative to the layer's folder, so the
    same run of a take moved or copied elsewhere gives the same bytes, and the file is an
    input of the layer, identified by its content like the layers it read. The take root
    the layer goes into (import's --root) is where it is written, not what it read.
    """
    from facedyn.usd.stage import relative_asset_path

    typed = {p.name: p.type for p in processor.parameters}
    written = Path(root).resolve() if root is not None else None
    recorded, files = {}, []
    for name, value in request.params.items():
        if typed.get(name) is Path and value is not None:
            recorded[name] = relative_asset_path(value, request.output.parent)
            if Path(value).is_file() and Path(value).resolve() != written:
                files.append(Path(value).resolve())
        else:
            recorded[name] = _plain(value)
    return recorded, files


def _with_files(inputs: list, files: list[Path], output: Path) -> list:
    """inputs and, after them, the files not among them already (by real path; labels name no file),
    less the output itself: a re-run that read its own earlier result through another take (a
    take's own root given as its skull motion) would otherwise be stale the moment it is written."""
    from facedyn.usd.runs import LayerInput

    written = Path(output).resolve()

    def path(i) -> Path:
        return Path(i.path if isinstance(i, LayerInput) else i)

    named = {path(i).resolve() for i in inputs if path(i).is_absolute()}
    return [i for i in inputs if not (path(i).is_absolute() and path(i).resolve() == written)] + \
        [f for f in files if f not in named and f != written]


def _plain(value: Any) -> Any:
    return str(value) if isinstance(value, Path) else value
