"""The state of a take's layer stack: each layer's role, coverage and staleness.

A layer is stale when what it was computed from is no longer what lies below it: the
content of a layer below changed (re-run, replaced, or edited by hand), a layer was added
below it, reordered, muted or removed, or another input it read (a model file) changed.
Inputs are identified by content (facedyn.usd.runs), so a take folder moved or copied
stays current, and an input that cannot be found from here (a model left behind when the
folder was copied) is reported as unchecked, not stale: nothing says its content changed.
A captured layer is the take's content; the source it was imported from is its history,
never checked. Layers written before inputs were identified by content are checked by the
runs they recorded (an edit that kept a layer's run cannot be seen: they say so, as
unchecked); layers written before inputs carried any id are never reported stale.

`stack_status` is the one place that decides each layer's state (`LayerStatus.state`):
`usdfacedyn layers`, `inspect` and `validate` all read it. Everything is read from the
files' metadata and bytes, nothing is composed.
"""
from __future__ import annotations

import math

import os
from dataclasses import asdict, dataclass
from pathlib import Path

from pxr import Sdf, Tf, Usd

from facedyn.errors import UsageError
from facedyn.io.files import special_file_kind
from facedyn.performance import CAPTURED, roles
from facedyn.usd.errors import TakeError
from facedyn.usd.layerstack import Entry, effective_ranks, is_take_root, recorded_role_name
from facedyn.usd.runs import INPUT_IDENTITY, LAYER, content_id, facedyn_metadata, legacy_id
from facedyn.usd.schema import recorded_inputs
from facedyn.usd.stage import relative_asset_path, resolve_asset_path

LEGACY_UNCHECKED = "written before inputs were identified by content: checked by the runs it recorded; re-run it to check content"
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
    needs: str = ""  # the role it is computed from, when no layer of that role lies below it
    unchecked: str = ""  # what of its inputs' content could not be checked (an input not found from here, an older layer)
    unreadable: str = ""  # why USD cannot open the file (damaged, cut short, a FIFO): every reader of the take refuses it

    @property
    def state(self) -> str:
        """muted, missing, unreadable, stale (or fed by nothing of the role it reads) or ok: what `layers` prints and validate reports."""
        if self.muted:
            return "muted"
        if not self.exists:
            return "missing"
        if self.unreadable:
            return "unreadable"
        return "stale" if self.stale or self.needs else "ok"

    @property
    def covers(self) -> bool:
        """True unless the layer is known to cover fewer frames than the take."""
        if self.frames is None or self.take_frames is None:
            return True
        return self.frames[0] <= self.take_frames[0] and self.frames[1] >= self.take_frames[1]

    def as_dict(self) -> dict:
        d = asdict(self)
        d.update(path=str(self.path), covers=self.covers, state=self.state)
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


def check_take_root(path: str | os.PathLike) -> None:
    """Raise a TakeError unless path is a take root (a layer that lists a take's layers), naming the root that lists it if one is beside it."""
    path = Path(path)
    if is_take_root(open_root(path)):
        return
    roots = _roots_listing(path)
    hint = f"; its take root is {roots[0]}" if roots else "; give the take's root (take.usda), which lists its layers"
    raise TakeError(f"{path}: not a take root, it lists no layers{hint}")


def _roots_listing(path: Path) -> list[Path]:
    """The take roots in path's folder that list it (in their subLayers or as muted)."""
    target, found = path.resolve(), []
    for candidate in sorted(path.parent.iterdir()):
        if candidate.resolve() == target or not candidate.is_file() or candidate.suffix.lower() not in (".usda", ".usd", ".usdc"):
            continue
        try:
            layer = Sdf.Layer.OpenAsAnonymous(str(candidate), metadataOnly=True)
        except Tf.ErrorException:
            continue
        if layer is not None and is_take_root(layer) and any(
                resolve_asset_path(a, candidate.parent) == target for a in list(layer.subLayerPaths) + muted_assets(layer)):
            found.append(candidate)
    return found


def muted_assets(layer: Sdf.Layer) -> list[str]:
    data = dict(layer.customLayerData).get("facedyn")
    return [str(a) for a in data.get(MUTED_KEY, [])] if isinstance(data, dict) else []


def read_entries(layer: Sdf.Layer, anchor_dir: Path, assets: list[str] | None = None) -> list[Entry]:
    known = roles()
    return [Entry.read(a, anchor_dir, known) for a in (layer.subLayerPaths if assets is None else assets)]


def stack_status(root: str | os.PathLike, below_rank: int | None = None) -> list[LayerStatus]:
    """Every layer of the root, strongest first, then the layers muted on disk.

    below_rank: only the unmuted layers of a lower rank (what a step of that rank reads), so
    that checking them does not hash the layers above (the step's own old output among them).
    """
    root = Path(root)
    layer = open_root(root)
    itself = root.resolve()
    entries = [e for e in read_entries(layer, root.parent) if e.path != itself]  # a self-listing is reported by lists_itself
    muted = read_entries(layer, root.parent, muted_assets(layer))
    take = take_frames(layer, entries)
    ranks = effective_ranks(entries)
    known = roles()
    statuses = []
    for i, entry in enumerate(entries):
        if below_rank is not None and (entry.rank is None or entry.rank >= below_rank):
            continue
        below = [e for e, r in zip(entries[i + 1 :], ranks[i + 1 :]) if r < ranks[i]]
        reason, unchecked = staleness(entry, below)
        needs = known[entry.role_name].reads if entry.role_name in known else None
        missing_source = needs if needs and not any(e.role_name == needs for e in entries[i + 1 :]) else ""
        statuses.append(_status(entry, False, take, reason, missing_source, unchecked))
    return statuses if below_rank is not None else statuses + [_status(entry, True, take, "") for entry in muted]


def _status(entry: Entry, muted: bool, take: tuple[float, float] | None, reason: str, needs: str = "",
            unchecked: str = "") -> LayerStatus:
    special = special_file_kind(entry.path)
    exists = entry.path.is_file() or special is not None
    return LayerStatus(
        asset=entry.asset, path=entry.path, role=entry.role_name, processor=entry.processor,
        rank=entry.rank, muted=muted, exists=exists, frames=frame_range(entry.metadata),
        take_frames=take, stale=bool(reason), reason=reason, needs=needs, unchecked=unchecked,
        unreadable=_unreadable(entry.path, special) if exists else "",
    )


def _unreadable(path: Path, special: str | None) -> str:
    """Why USD cannot open the whole layer file ("" when it can). A special file is never opened (a FIFO would block);
    the metadata of a text layer cut short still reads, a damaged one's not at all (it then looks like a plain layer).
    A crate file opens without reading its arrays."""
    if special is not None:
        return f"is {special}, not a USD file; facedyn opens only regular files"
    try:
        if Sdf.Layer.OpenAsAnonymous(str(path)) is not None:
            return ""
    except Tf.ErrorException:
        pass
    return "not a readable USD file (damaged or truncated?)"


def stale_below(root: str | os.PathLike, role_name: str) -> list[LayerStatus]:
    """The layers a step writing role_name would read (those of lower rank) that are stale or missing."""
    return [s for s in stack_status(root, below_rank=roles()[role_name].rank) if s.state in ("stale", "missing")]


def lists_itself(root: str | os.PathLike) -> str | None:
    """The entry by which a take root lists itself among its subLayers (None when it does not)."""
    root = Path(root)
    itself = root.resolve()
    layer = open_root(root)
    return next((a for a in list(layer.subLayerPaths) if resolve_asset_path(a, root.parent) == itself), None)


def check_not_self_listing(root: str | os.PathLike) -> None:
    """Refuse a take root that lists itself: USD only warns, and composes the rest as if it did not."""
    itself = lists_itself(root)
    if itself is not None:
        raise UsageError(f"{root}: lists itself among its subLayers ({itself}); take that entry out first: "
                         f"usdfacedyn layers {root} --detach {itself}")


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


def staleness(entry: Entry, below: list[Entry]) -> tuple[str, str]:
    """Why `entry` no longer matches what it was computed from ("" when it still does), and an input it could not check.

    Compared: the layers below it with the layers it read (same files, same content, same
    order, none gone), and its other inputs' content where they can be found.
    """
    data = entry.metadata
    if not data or "run" not in data or not entry.path.is_file():
        return "", ""
    identify = content_id if data.get("inputIdentity") == INPUT_IDENTITY else legacy_id
    anchor = entry.path.parent
    recorded = [(resolve_asset_path(i["layer"], anchor), i["run"], i["kind"]) for i in recorded_inputs(data) if i["run"]]
    recorded_paths = [p for p, _, _ in recorded]
    positions = []
    for layer in below:
        if layer.path not in recorded_paths:
            return f"{layer.asset} lies below it but is not what it was computed from", ""
        position = recorded_paths.index(layer.path)
        now = identify(layer.path)
        if now != recorded[position][1]:
            return f"its input {layer.asset} changed since (content {recorded[position][1]}, now {now or 'gone'})", ""
        positions.append(position)
    if positions != sorted(positions):
        return "the layers below it were reordered since it was computed", ""
    below_paths = {layer.path for layer in below}
    legacy = identify is legacy_id and recorded and entry.role_name != CAPTURED
    unchecked = LEGACY_UNCHECKED if legacy else ""
    for path, run, kind in recorded:
        if path in below_paths:
            continue
        name = relative_asset_path(path, anchor)
        if _was_stack_layer(kind, path):
            return f"its input {name} is no longer below it (muted, detached or gone)", ""
        if entry.role_name == CAPTURED:
            continue  # the capture is the take's content; its source is history
        if not path.is_file():
            unchecked = unchecked or f"its input {name} is not found from here; its content was not checked"
        elif identify(path) != run:
            return f"its input {name} changed since it was computed", ""
    return "", unchecked


def _was_stack_layer(kind: str, path: Path) -> bool:
    """Whether a recorded input was a layer of the stack the run read (older layers: a facedyn layer with a role)."""
    if kind:
        return kind == LAYER
    return path.is_file() and recorded_role_name(facedyn_metadata(path)) is not None


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
        frames = f"{s.frames[0]:g}..{s.frames[1]:g}" if s.frames else "-"
        if not s.covers:
            frames += f" (take {s.take_frames[0]:g}..{s.take_frames[1]:g})"
        lines.append(f"{s.asset:<36} {s.role or '-':<12} {s.processor or '-':<12} {frames:<24} {s.state}")
        if s.unreadable:
            lines.append(f"    unreadable: {s.unreadable}; every reader of the take refuses it")
        if s.stale:
            lines.append(f"    stale: {s.reason}")
        if s.needs:
            lines.append(f"    stale: {needs_message(s)}")
        if s.unchecked:
            lines.append(f"    unchecked: {s.unchecked}")
    return "\n".join(lines)


def needs_message(status: LayerStatus) -> str:
    return f"a {status.role} layer needs a {status.needs} layer below it, and none is"
