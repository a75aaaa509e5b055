"""Opening USD files with errors a user can act on, and naming them in asset paths."""
from __future__ import annotations

import os
from pathlib import Path

from pxr import Sdf, Tf, Usd, UsdGeom

from facedyn.io.files import special_file_kind
from facedyn.usd.errors import TakeError
from facedyn.usd.takechecks import CENTIMETRES, scale_problem


def open_stage(path: str | os.PathLike) -> Usd.Stage:
    """Open a USD file, or raise a one-line TakeError naming it (missing, unreadable, not USD)."""
    path = Path(path)
    try:
        str(path).encode("utf-8")
    except UnicodeEncodeError:
        raise TakeError(f"{path}: the path is not valid UTF-8, which USD needs for file names; rename it") from None
    if not path.exists():
        raise TakeError(f"{path}: no such file")
    if path.is_dir():
        raise TakeError(f"{path}: is a folder, expected a USD file")
    kind = special_file_kind(path)
    if kind is not None:
        raise TakeError(f"{path}: is {kind}, not a USD file; facedyn opens only regular files")
    if not path.suffix.lstrip(".") or not Sdf.FileFormat.FindByExtension(path.suffix.lstrip(".")):
        raise TakeError(f"{path}: not a USD file (unknown extension {path.suffix!r})")
    try:
        layers = _open_layer_files(path)  # held open while the stage composes them, so each is read once
        stage = Usd.Stage.Open(layers[0], Usd.Stage.LoadAll)
    except Tf.ErrorException:
        raise TakeError(f"{path}: not a readable USD file (the USD parser rejected it)") from None
    if stage is None:
        raise TakeError(f"{path}: not a readable USD file")
    return stage


MAX_LAYER_FILES = 100_000  # layers of one stage's sublayers, references and payloads, walked before it opens


def _open_layer_files(path: Path) -> list[Sdf.Layer]:
    """The layer at `path` and every local layer file it composes (sublayers, references,
    payloads, recursively), each checked to be a regular file before USD opens it.

    USD opens what a layer names without asking: a sublayer that is a FIFO would block the
    stage's opening forever, a device would never end. Opening the layers here, in the order
    USD would, lets each asset be checked first; USD then finds them already open.
    """
    layers: list[Sdf.Layer] = []
    seen: set[str] = set()
    pending = [(str(path), None)]
    while pending and len(layers) < MAX_LAYER_FILES:
        file, named_by = pending.pop()
        if file in seen:
            continue
        seen.add(file)
        kind = special_file_kind(file)
        if kind is not None:
            where = f"{named_by}: names {file}, which" if named_by else file
            raise TakeError(f"{where} is {kind}, not a USD file; facedyn opens only regular files")
        if named_by is not None and not os.path.isfile(file):
            continue  # missing or a folder: USD reports it as it composes
        try:
            layer = Sdf.Layer.FindOrOpen(file)
        except Tf.ErrorException:
            layer = None
        if layer is None:
            if named_by is None:
                raise TakeError(f"{path}: not a readable USD file (the USD parser rejected it)")
            raise TakeError(f"{named_by}: names {file}, which is not a readable USD file (damaged or truncated?)")
        problem = _scale_problem(layer)
        if problem:
            raise TakeError(f"{layer.realPath or file}: {problem} (fix the layer's metadata; facedyn will not guess it)")
        layers.append(layer)
        for asset in layer.GetCompositionAssetDependencies():
            if asset and not Sdf.Layer.IsAnonymousLayerIdentifier(asset):
                pending.append((layer.ComputeAbsolutePath(asset), layer.realPath or layer.identifier))
    return layers


def _scale_problem(layer: Sdf.Layer) -> str | None:
    """Why a layer's authored metersPerUnit or rates cannot be composed (takechecks.scale_problem), or None.

    Checked before the stage composes: a rate of 0 maps every time sample of the layers
    below onto one time code (USD scales their times by the ratio of rates).
    """
    info = layer.pseudoRoot
    meters = info.GetInfo(UsdGeom.Tokens.metersPerUnit) if info.HasInfo(UsdGeom.Tokens.metersPerUnit) else CENTIMETRES
    rates = (layer.timeCodesPerSecond if layer.HasTimeCodesPerSecond() else 24.0,
             layer.framesPerSecond if layer.HasFramesPerSecond() else 24.0)
    return scale_problem(float(meters), *map(float, rates))


def get_prim(stage: Usd.Stage, prim_path: str) -> Usd.Prim:
    """The prim at prim_path, or a TakeError naming the file and the path."""
    try:
        sdf_path = Sdf.Path(prim_path)
    except Tf.ErrorException:
        raise TakeError(f"{layer_name(stage)}: {prim_path!r} is not a valid prim path") from None
    prim = stage.GetPrimAtPath(sdf_path) if sdf_path.IsAbsolutePath() else Usd.Prim()
    if not prim:
        raise TakeError(f"{layer_name(stage)}: no prim at {prim_path}")
    return prim


def layer_name(stage: Usd.Stage) -> str:
    return stage.GetRootLayer().realPath or stage.GetRootLayer().identifier



def relative_asset_path(target: str | os.PathLike, anchor_dir: str | os.PathLike) -> str:
    """target as a path relative to anchor_dir, in USD's './x' form when possible."""
    rel = os.path.relpath(Path(target).resolve(), Path(anchor_dir).resolve())
    rel = rel.replace(os.sep, "/")
    return rel if rel.startswith("../") else "./" + rel


def resolve_asset_path(entry: str, anchor_dir: str | os.PathLike) -> Path:
    """The real file an asset path written in a layer of anchor_dir names (symlinks resolved)."""
    return (Path(anchor_dir) / entry).resolve()
