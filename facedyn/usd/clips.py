"""Long layers as USD value clips: one clip layer per chunk of frames, metadata in the layer.

A layer past `CLIP_THRESHOLD` frames is never built whole in memory: its per-frame values go
to clip layers in a folder beside it (`<stem>.<run>.clips/<stem>.NNNN.usdc`, one per chunk,
each written as soon as its chunk is computed), and the layer itself keeps the static
values plus a clip set (`clips` metadata: assetPaths, active, times, primPath,
manifestAssetPath) on the skull prim. USD composes the clips itself, so readers, usdview,
inspect and validate see the same values as in a single layer. Each layer's clip set has
its own name, so clipped layers stacked on one another keep their order of strength.

The folder is named after the layer's run id and filled under a temporary name, so the
layer's atomic rename switches from the old clips to the new ones in one step; folders of
earlier runs are removed after it.
"""
from __future__ import annotations

import os
import re
import shutil
from pathlib import Path

from pxr import Sdf, Vt

CLIP_THRESHOLD = 5000  # frames: longer layers are written as value clips
CLIPS_SUFFIX = ".clips"


def clip_set_name(path: Path) -> str:
    """The layer's own clip set name (a valid identifier): stacked clipped layers must not share one."""
    return "facedyn_" + re.sub(r"\W", "_", path.stem)


def clips_folder(path: Path, run: str) -> Path:
    """Where the clips of the layer at `path`, written by run `run`, live."""
    return path.parent / f"{path.stem}.{run}{CLIPS_SUFFIX}"


def _declare_attributes(source: Sdf.Layer, target: Sdf.Layer, attribute_paths: list[Sdf.Path]) -> None:
    """Create in `target` the attributes (as overs, with their types, no values) that `source` declares."""
    for attr_path in attribute_paths:
        prim = Sdf.CreatePrimInLayer(target, attr_path.GetPrimPath())
        if prim.specifier != Sdf.SpecifierDef:
            prim.specifier = Sdf.SpecifierOver
        declared = source.GetAttributeAtPath(attr_path)
        if prim.attributes.get(attr_path.name) is None:
            Sdf.AttributeSpec(prim, attr_path.name, declared.typeName, declared.variability, declared.custom)


class ClipWriter:
    """Writes a long layer's chunks as clip layers into a temporary folder, then places them.

    layer: the (in-memory) layer that declares every time-varying attribute and gets the
    clip metadata; anchor: the prim whose namespace the clips cover (the skull); varying:
    the attribute paths the chunks author.
    """

    def __init__(self, path: Path, run: str, layer: Sdf.Layer, anchor: Sdf.Path, varying: list[Sdf.Path], export):
        self.path, self.layer, self.anchor, self.varying, self.export = path, layer, anchor, varying, export
        self.folder = clips_folder(path, run)
        self.staging = path.parent / f".{self.folder.name}.{os.getpid()}.tmp"
        shutil.rmtree(self.staging, ignore_errors=True)
        self.staging.mkdir()
        self.assets: list[Sdf.AssetPath] = []
        self.active: list[tuple[float, float]] = []
        self.first = self.last = None

    def new_clip(self) -> Sdf.Layer:
        """An empty clip layer declaring the varying attributes, to author one chunk's samples in."""
        clip = Sdf.Layer.CreateAnonymous(".usdc")
        _declare_attributes(self.layer, clip, self.varying)
        return clip

    def add(self, clip: Sdf.Layer, first: float, last: float) -> None:
        """Write one chunk's clip layer (frames first..last) into the folder."""
        name = f"{self.path.stem}.{len(self.assets):04d}.usdc"
        self.export(clip, self.staging / name)
        self.assets.append(Sdf.AssetPath(f"./{self.folder.name}/{name}"))
        self.active.append((float(first), float(len(self.active))))
        self.first = first if self.first is None else self.first
        self.last = last

    def finish(self) -> None:
        """Write the manifest, author the clip set on the layer, and move the folder into place."""
        manifest = Sdf.Layer.CreateAnonymous(".usda")
        _declare_attributes(self.layer, manifest, self.varying)
        self.export(manifest, self.staging / "manifest.usda")
        clip_set = {
            "assetPaths": Sdf.AssetPathArray(self.assets),
            "primPath": str(self.anchor),
            "active": Vt.Vec2dArray(self.active),
            "times": Vt.Vec2dArray([(self.first, self.first), (self.last, self.last)]),  # clip time = stage time
            "manifestAssetPath": Sdf.AssetPath(f"./{self.folder.name}/manifest.usda"),
        }
        # authored on the spec (no stage composed here: the clips' relative paths resolve once the layer is on disk)
        self.layer.GetPrimAtPath(self.anchor).SetInfo("clips", {clip_set_name(self.path): clip_set})
        shutil.rmtree(self.folder, ignore_errors=True)  # an earlier run with the same id: the same content
        os.replace(self.staging, self.folder)

    def discard(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)


def remove_other_clips(path: Path, keep: Path | None) -> None:
    """Remove clip folders of earlier runs of the layer at `path` (all of them when keep is None)."""
    for folder in path.parent.glob(f"{glob_escape(path.stem)}.*{CLIPS_SUFFIX}"):
        if folder != keep and folder.is_dir() and folder.name.count(".") == path.stem.count(".") + 2:
            shutil.rmtree(folder, ignore_errors=True)


def glob_escape(text: str) -> str:
    return re.sub(r"([*?\[])", r"[\1]", text)
