"""The state of a take's layer stack: each layer's role, coverage and staleness.

A layer is stale when what it was computed from is no longer what lies below it: a layer
below it was re-run (its run id changed), replaced, added, reordered or removed, or another
input (a model file, a source mesh) changed or vanished. Its recorded inputs say which
(facedyn.usd.runs); layers written before inputs carried run ids cannot be checked and are
never reported stale. Everything is read from the files' metadata, nothing is composed.
"""
from __future__ import annotations

import math

import os
from dataclasses import asdict, dataclass
from pathlib import Path

from pxr import Sdf, Tf, Usd

from facedyn.performance import roles
from facedyn.usd.errors import TakeError
from facedyn.usd.layerstack import CAPTURED, Entry, effective_ranks
from facedyn.usd.runs import current_run
from facedyn.usd.schema import recorded_inputs
from facedyn.usd.stage import relative_asset_path, resolve_asset_path

MUTED_KEY = "muted"  # root customLayerData["facedyn"][MUTED_KEY]: entries muted on disk


@dataclass(frozen=True)
class LayerStatus:
    """One layer of a take root, as `usdfacedyn layers` lists it."""

    asset: str  # as written in the root's subLayers (or its muted list)
    path: Path
    role: str | None  # the recorded role name (None: not a facedyn result layer)
    processor: str | None
    rank: int | None  # None: no installed package declares the role
    muted: bool  # muted on disk: out of subLayers, remembered in the root's metadata
    exists: bool
    frames: tuple[float, float] | None  # the frames the layer covers
    take_frames: tuple[float, float] | None  # the take's frames (its capture's)
    stale: bool
    reason: str  # why it is stale ("" when it is not)

    @property
    def covers(self) -> bool:
        """True unless the layer is known to cover fewer frames than the take."""
        if self.frames is None or self.take_frames is None:
            return True
        return self.frames[0] <= self.take_frames[0] and self.frames[1] >= self.take_frames[1]

    def as_dict(self) -> dict:
        d = asdict(self)
        d.update(path=str(self.path), covers=self.covers)
        return d


def open_root(root: str | os.PathLike, metadata_only: bool = True) -> Sdf.Layer:
    """The root layer as it is on disk now (a fresh anonymous copy), or a TakeError naming it."""
    root = Path(root)
    if not root.is_file():
        raise TakeError(f"{root}: no such take root")
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(root), metadataOnly=metadata_only)
    except Tf.ErrorException:
        layer = None
    if layer is None:
        raise TakeError(f"{root}: not a readable USD layer")
    return layer


def muted_assets(layer: Sdf.Layer) -> list[str]:
    data = dict(layer.customLayerData).get("facedyn")
    return [str(a) for a in data.get(MUTED_KEY, [])] if isinstance(data, dict) else []


def read_entries(layer: Sdf.Layer, anchor_dir: Path, assets: list[str] | None = None) -> list[Entry]:
    known = roles()
    return [Entry.read(a, anchor_dir, known) for a in (layer.subLayerPaths if assets is None else assets)]


def stack_status(root: str | os.PathLike) -> list[LayerStatus]:
    """Every layer of the root, strongest first, then the layers muted on disk."""
    root = Path(root)
    layer = open_root(root)
    entries = read_entries(layer, root.parent)
    muted = read_entries(layer, root.parent, muted_assets(layer))
    take = take_frames(layer, entries)
    ranks = effective_ranks(entries)
    statuses = []
    for i, entry in enumerate(entries):
        below = [e for e, r in zip(entries[i + 1 :], ranks[i + 1 :]) if r < ranks[i]]
        statuses.append(_status(entry, False, take, staleness(entry, below)))
    return statuses + [_status(entry, True, take, "") for entry in muted]


def _status(entry: Entry, muted: bool, take: tuple[float, float] | None, reason: str) -> LayerStatus:
    return LayerStatus(
        asset=entry.asset, path=entry.path, role=entry.role_name, processor=entry.processor,
        rank=entry.rank, muted=muted, exists=entry.path.is_file(), frames=frame_range(entry.metadata),
        take_frames=take, stale=bool(reason), reason=reason,
    )


def frame_range(data: dict | None) -> tuple[float, float] | None:
    """The (first, last) frames a layer records; None when it records none or something malformed."""
    try:
        first, last = (float(f) for f in data["frameRange"])
    except (TypeError, ValueError, KeyError):
        return None
    return (first, last) if math.isfinite(first) and math.isfinite(last) else None


def take_frames(root_layer: Sdf.Layer, entries: list[Entry]) -> tuple[float, float] | None:
    """The take's frames: its capture's (the weakest captured layer), else the root's time codes."""
    captured = [e for e in entries if e.role_name == CAPTURED and frame_range(e.metadata)]
    if captured:
        return frame_range(captured[-1].metadata)
    if root_layer.HasStartTimeCode() and root_layer.HasEndTimeCode():
        return float(root_layer.startTimeCode), float(root_layer.endTimeCode)
    return None


def staleness(entry: Entry, below: list[Entry]) -> str:
    """Why `entry` no longer matches what it was computed from ("" when it still does)."""
    data = entry.metadata
    if not data or "run" not in data or not entry.path.is_file():
        return ""
    anchor = entry.path.parent
    recorded = [(resolve_asset_path(i["layer"], anchor), i["run"]) for i in recorded_inputs(data) if i["run"]]
    recorded_paths = [p for p, _ in recorded]
    positions = []
    for layer in below:
        if layer.path not in recorded_paths:
            return f"{layer.asset} lies below it but is not what it was computed from"
        position = recorded_paths.index(layer.path)
        now = current_run(layer.path)
        if now != recorded[position][1]:
            return f"its input {layer.asset} changed since (run {recorded[position][1]}, now {now or 'gone'})"
        positions.append(position)
    if positions != sorted(positions):
        return "the layers below it were reordered since it was computed"
    below_paths = {layer.path for layer in below}
    for path, run in recorded:
        if path in below_paths:
            continue
        name = relative_asset_path(path, anchor)
        if not path.is_file():
            return f"its input {name} is gone"
        if current_run(path) != run:
            return f"its input {name} changed since it was computed"
    return ""


def covers_take(root_or_stage: str | os.PathLike | Usd.Stage, frames: tuple[float, float]) -> bool:
    """Whether a layer covering frames (first, last) covers the whole take (True when the take's frames are unknown)."""
    if isinstance(root_or_stage, Usd.Stage):
        root_or_stage = root_or_stage.GetRootLayer().realPath
    root = Path(root_or_stage)
    layer = open_root(root)
    take = take_frames(layer, read_entries(layer, root.parent))
    return take is None or (frames[0] <= take[0] and frames[1] >= take[1])


def format_layers(statuses: list[LayerStatus]) -> str:
    """The stack as a table, strongest first (what `usdfacedyn layers TAKE` prints)."""
    lines = []
    for s in statuses:
        state = "muted" if s.muted else ("missing" if not s.exists else ("stale" if s.stale else "ok"))
        frames = f"{s.frames[0]:g}..{s.frames[1]:g}" if s.frames else "-"
        if not s.covers:
            frames += f" (take {s.take_frames[0]:g}..{s.take_frames[1]:g})"
        lines.append(f"{s.asset:<36} {s.role or '-':<12} {s.processor or '-':<12} {frames:<24} {state}")
        if s.stale:
            lines.append(f"    stale: {s.reason}")
    return "\n".join(lines)
