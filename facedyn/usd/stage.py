"""Opening USD files with errors a user can act on, and naming them in asset paths."""
from __future__ import annotations

import os
from pathlib import Path

from pxr import Sdf, Tf, Usd

from facedyn.usd.errors import TakeError


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
    if not Sdf.FileFormat.FindByExtension(path.suffix.lstrip(".")):
        raise TakeError(f"{path}: not a USD file (unknown extension {path.suffix!r})")
    try:
        stage = Usd.Stage.Open(str(path), Usd.Stage.LoadAll)
    except Tf.ErrorException:
        raise TakeError(f"{path}: not a readable USD file (the USD parser rejected it)") from None
    if stage is None:
        raise TakeError(f"{path}: not a readable USD file")
    return stage


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
