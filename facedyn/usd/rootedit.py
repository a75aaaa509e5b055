"""Editing a take root's subLayers: placed by role, under a file lock, rewritten atomically.

Every change to a root (attaching a result, muting, unmuting, detaching, reordering) is a
read-modify-write of one small .usda file. Two processes attaching at once would both read
the old list, and the second rename would drop the first one's entry; so each edit holds an
exclusive lock on the root for the whole read-modify-write, then renames the new root into
place (`export_atomically`), so a reader never sees half a file.

Muting on disk takes a layer out of subLayers and remembers it in the root's
customLayerData["facedyn"]["muted"], so that `unmute` can put it back at its role's place.
The actor a take belongs to (`import --actor`) is kept there too, as customLayerData
["facedyn"]["actor"]: an asset path relative to the root, read back by `recorded_actor`.
"""
from __future__ import annotations

import fcntl
import os
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from pxr import Sdf, Tf, Vt

from facedyn.errors import UsageError
from facedyn.performance import CAPTURED, roles
from facedyn.performance import role as find_role
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import check_writable, export_atomically, new_take_root
from facedyn.usd.layerstack import Entry, effective_ranks, place, recorded_role_name
from facedyn.usd.runs import facedyn_metadata
from facedyn.usd.stackstatus import (MUTED_KEY, check_take_root, frame_range, muted_assets, open_root, read_entries, stack_status,
                                     take_frames)
from facedyn.usd.stage import relative_asset_path, resolve_asset_path
from facedyn.usd.timing import Timing

LOCK_MODE = 0o644
ACTOR_KEY = "actor"  # root customLayerData["facedyn"][ACTOR_KEY]: the take's actor asset, relative to the root


def _lock_file(root: str | os.PathLike) -> Path:
    """The kept `.NAME.lock` file beside a take root that `_root_lock` flocks."""
    root = Path(root)
    return root.parent / f".{root.name}.lock"


def remove_created_root(root: Path, layer: Path) -> None:
    """After a failed run, the take root it created (if it lists nothing but this run's layer) and the root's lock file.

    A root this run made and could not finish would be a broken take.usda, and its lock
    file alone would keep the output's folder from being removed. The lock file goes only
    when no one holds it and no root is left for it to guard.
    """
    if root.is_file():
        try:
            listed = Sdf.Layer.OpenAsAnonymous(str(root), metadataOnly=True)
        except Tf.ErrorException:  # a root left half-written: nothing in it to keep
            listed = None
        others = [a for a in (listed.subLayerPaths if listed else []) if (root.parent / a).resolve() != layer.resolve()]
        if others:
            return
        root.unlink()
    try:
        fd = os.open(_lock_file(root), os.O_RDWR)
    except OSError:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        if not root.exists():
            _lock_file(root).unlink()
    except OSError:
        pass  # another run holds it: its root is its own
    finally:
        os.close(fd)


@contextmanager
def _root_lock(root: str | os.PathLike) -> Iterator[None]:
    """Hold an exclusive advisory lock on root: flock on a kept `.NAME.lock` file beside it.

    Why this lock: flock belongs to the open file, so two edits in one process exclude each
    other as well as two processes do, and it is released when the process dies, so a
    crashed run never leaves the take locked. The lock file is a separate, kept file: the
    root itself is replaced by a rename on every edit (a lock on it would stay on the old
    inode), and deleting the lock file after use would let a newcomer lock a fresh file
    while a waiter still holds the old one. Advisory: it holds off facedyn and any tool that
    takes the same lock, not a text editor.
    """
    root = Path(root)
    lock_path = _lock_file(root)
    try:
        fd = os.open(lock_path, os.O_RDWR | os.O_CREAT, LOCK_MODE)
    except OSError as exc:
        raise TakeError(f"{root}: cannot lock the take root ({exc.strerror}: {lock_path})") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)  # releases the lock


@dataclass
class AttachReport:
    """What attaching a layer did to a root."""

    root: Path
    layer: Path
    role: str
    sublayers: list[str]  # the root's subLayers afterwards, strongest first
    replaced: list[str] = field(default_factory=list)  # entries of the same role it replaced
    stale: list[str] = field(default_factory=list)  # entries above it that are now stale
    created: bool = False  # the root was created for it

    def as_dict(self) -> dict:
        return {"root": str(self.root), "layer": str(self.layer), "role": self.role, "sublayers": self.sublayers,
                "replaced": self.replaced, "stale": self.stale, "created": self.created}


def attach(root: str | os.PathLike, layer_path: str | os.PathLike, role_name: str | None = None,
           create_with: Timing | None = None) -> AttachReport:
    """Place layer_path in root's subLayers by its role (the one it records, or role_name).

    A re-run of a non-variant role replaces that role's entry in place, even under another
    file name; a variant becomes the strongest of its rank. A root that does not exist is
    created with `create_with`'s timing (import), else it is an error.
    """
    with _root_lock(root):
        return _attach(Path(root), Path(layer_path), role_name, create_with)


def attach_written_layer(root: str | os.PathLike, layer_path: str | os.PathLike, role_name: str,
                         write: Callable[[], object], create_with: Timing | None = None,
                         actor: str | os.PathLike | None = None) -> AttachReport:
    """Lock root, check it can be edited, `write()` the layer, attach it, unlock.

    If anything after the write fails, a layer that did not exist before is removed again,
    so a failed attach leaves no orphan behind. `actor` (an actor asset) is recorded in the
    root in the same edit.
    """
    root, layer_path = Path(root), Path(layer_path)
    existed = layer_path.exists()
    with _root_lock(root):
        if root.exists() or create_with is None:
            _check_editable(root)
        else:
            check_writable(root)
        write()
        try:
            return _attach(root, layer_path, role_name, create_with, actor)
        except BaseException:
            if not existed:
                layer_path.unlink(missing_ok=True)
            raise


def _check_editable(root: Path) -> Sdf.Layer:
    """The root read fresh from disk, after checking it can be rewritten."""
    layer = open_root(root, metadata_only=False)
    check_writable(root)
    if not root.stat().st_mode & 0o222:
        raise TakeError(f"{root}: the take root is read-only (chmod u+w it to change its layers)")
    return layer


def _attach(root: Path, layer_path: Path, role_name: str | None, create_with: Timing | None,
            actor: str | os.PathLike | None = None) -> AttachReport:
    if layer_path.resolve() == root.resolve():
        raise UsageError(f"{layer_path}: a take root cannot list itself")
    if not layer_path.is_file():
        raise TakeError(f"{layer_path}: no such layer to attach")
    data = facedyn_metadata(layer_path)
    name = role_name or recorded_role_name(data)
    if name is None:
        raise TakeError(f"{layer_path}: records no facedyn role; say which role it plays")
    try:
        role = find_role(name)
    except ValueError as exc:
        raise TakeError(f"{layer_path}: {exc}") from None
    created = not root.exists()
    if created:
        if create_with is None:
            raise TakeError(f"{root}: no such take root to attach to")
        layer = new_take_root(create_with)
    else:
        layer = _check_editable(root)
    _check_no_cycle(root, layer_path)
    entries = read_entries(layer, root.parent)
    layer_frames = frame_range(data)
    take = take_frames(layer, entries)
    if take is not None and layer_frames is not None and role.name != CAPTURED and (layer_frames[0] > take[0] or layer_frames[1] < take[1]):
        raise TakeError(
            f"{layer_path}: covers frames {layer_frames[0]:g}:{layer_frames[1]:g} but the take {root} covers "
            f"{take[0]:g}:{take[1]:g}; composed over it, the frames it lacks would hold its last value. "
            "Run without --frames, or write the partial layer without attaching it"
        )
    new = Entry(relative_asset_path(layer_path, root.parent), layer_path.resolve(), role, role.name,
                data.get("processor") if data else None, data)
    placed, replaced = place(entries, new)
    layer.subLayerPaths = [e.asset for e in placed]
    _set_muted(layer, [a for a in muted_assets(layer) if resolve_asset_path(a, root.parent) != new.path])
    if actor is not None:
        _set_facedyn_entry(layer, ACTOR_KEY, relative_asset_path(actor, root.parent))
    export_atomically(layer, root)
    above = {e.asset for e in placed[: placed.index(new)]}
    stale = [s.asset for s in stack_status(root) if s.asset in above and s.stale]
    return AttachReport(root, layer_path, role.name, [e.asset for e in placed], [e.asset for e in replaced], stale, created)


def _check_no_cycle(root: Path, layer_path: Path) -> None:
    """Refuse a layer that (through its own subLayers) lists the root it is attached to."""
    seen, todo, target = set(), [layer_path.resolve()], root.resolve()
    while todo:
        path = todo.pop()
        if path in seen or not path.is_file():
            continue
        seen.add(path)
        try:
            layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True)
        except Exception:
            continue
        for asset in layer.subLayerPaths if layer else []:
            child = resolve_asset_path(asset, path.parent)
            if child == target:
                raise UsageError(f"{layer_path}: lists {root} among its own layers; attaching it would make the root list itself")
            todo.append(child)


def _set_muted(layer: Sdf.Layer, assets: list[str]) -> None:
    _set_facedyn_entry(layer, MUTED_KEY, Vt.StringArray(assets) if assets else None)


def _set_facedyn_entry(layer: Sdf.Layer, key: str, value) -> None:
    """Set (or, with None, remove) one entry of the root's customLayerData["facedyn"]."""
    data = dict(layer.customLayerData)
    facedyn = dict(data.get("facedyn", {}))
    if value is None:
        facedyn.pop(key, None)
    else:
        facedyn[key] = value
    data["facedyn"] = facedyn
    layer.customLayerData = data


def recorded_actor(root: str | os.PathLike) -> Path | None:
    """The actor asset recorded in a take root (`import --actor`), or None; a recorded asset
    that is gone is an error naming both files."""
    root = Path(root)
    data = dict(open_root(root).customLayerData).get("facedyn")
    asset = data.get(ACTOR_KEY) if isinstance(data, dict) else None
    if not asset:
        return None
    path = resolve_asset_path(str(asset), root.parent)
    if not path.is_file():
        raise TakeError(f"{root}: records the actor {asset}, which does not exist ({path}); re-import with --actor ACTOR")
    return path


@contextmanager
def _editing(root: str | os.PathLike) -> Iterator[Sdf.Layer]:
    """The root, locked and read fresh; written back atomically when the block succeeds."""
    root = Path(root)
    check_take_root(root)
    with _root_lock(root):
        layer = _check_editable(root)
        yield layer
        export_atomically(layer, root)


def _lookup(name: str | os.PathLike, assets: list[str], root: Path) -> int | None:
    """The index in assets of the layer called name (an entry as written, or a file path), or None."""
    text = str(name)
    if text in assets:
        return assets.index(text)
    wanted = {Path(text).resolve(), resolve_asset_path(text, root.parent)}
    return next((i for i, asset in enumerate(assets) if resolve_asset_path(asset, root.parent) in wanted), None)


def _find(name: str | os.PathLike, assets: list[str], root: Path, where: str) -> int:
    """_lookup, or a UsageError listing what there is."""
    index = _lookup(name, assets, root)
    if index is None:
        raise UsageError(f"{root}: no layer {name} in its {where} (they are: {', '.join(assets) or 'none'})")
    return index


def mute(root: str | os.PathLike, layer: str | os.PathLike) -> list[str]:
    """Take a layer out of root's subLayers, remembering it as muted; return the subLayers left."""
    root = Path(root)
    with _editing(root) as edited:
        assets = list(edited.subLayerPaths)
        index = _find(layer, assets, root, "subLayers")
        _refuse_capture(root, assets[index], "muted")
        asset = assets.pop(index)
        edited.subLayerPaths = assets
        _set_muted(edited, muted_assets(edited) + [asset])
    return assets


def unmute(root: str | os.PathLike, layer: str | os.PathLike) -> list[str]:
    """Put a layer muted on disk back at its role's place; return the subLayers.

    A non-variant role whose place was taken meanwhile (a re-run) is an error; a layer of
    unknown role goes back as the strongest.
    """
    root = Path(root)
    with _editing(root) as edited:
        muted = muted_assets(edited)
        asset = muted.pop(_find(layer, muted, root, "muted layers"))
        entries = read_entries(edited, root.parent)
        new = read_entries(edited, root.parent, [asset])[0]
        taken = [e.asset for e in entries if new.role and not new.role.variants and e.role_name == new.role_name]
        if taken:
            raise UsageError(f"{root}: its {new.role_name} layer is now {taken[0]}; detach or mute it before unmuting {asset}")
        placed, _ = place(entries, new)
        edited.subLayerPaths = [e.asset for e in placed]
        _set_muted(edited, muted)
    return list(edited.subLayerPaths)


def detach(root: str | os.PathLike, layer: str | os.PathLike) -> list[str]:
    """Remove a layer from root (from its subLayers, or from its muted layers); return the subLayers."""
    root = Path(root)
    with _editing(root) as edited:
        assets, muted = list(edited.subLayerPaths), muted_assets(edited)
        index = _lookup(layer, assets, root)
        if index is not None:
            _refuse_capture(root, assets[index], "detached")
            assets.pop(index)
            edited.subLayerPaths = assets
        else:
            muted.pop(_find(layer, muted, root, "subLayers or muted layers"))
            _set_muted(edited, muted)
    return assets


def _refuse_capture(root: Path, asset: str, what: str) -> None:
    """The captured layer is the take itself: every other layer is computed from it, and it sets the take's frames."""
    if Entry.read(asset, root.parent, roles()).role_name == CAPTURED:
        raise UsageError(f"{root}: {asset} is the take's captured layer, which every other layer is computed from; it cannot "
                         f"be {what} (re-import the take to replace it)")


def move(root: str | os.PathLike, layer: str | os.PathLike, above: str | os.PathLike | None = None,
         below: str | os.PathLike | None = None) -> list[str]:
    """Move a layer just above or below another of the same rank (which variant shows); return the subLayers.

    Across ranks the order is the roles', not the user's: a stabilized layer above a
    quasistatic one would hide it, and every processor reads by rank.
    """
    if (above is None) == (below is None):
        raise UsageError("move needs exactly one of above= or below=")
    root = Path(root)
    with _editing(root) as edited:
        entries = read_entries(edited, root.parent)
        assets = [e.asset for e in entries]
        i = _find(layer, assets, root, "subLayers")
        j = _find(above if above is not None else below, assets, root, "subLayers")
        if i == j:
            raise UsageError(f"{root}: cannot move {assets[i]} relative to itself")
        ranks = effective_ranks(entries)
        if ranks[i] != ranks[j]:
            names = [f"{entries[k].asset} ({entries[k].role_name or 'no role'}, rank {ranks[k]:g})" for k in (i, j)]
            raise UsageError(
                f"{root}: cannot move {names[0]} next to {names[1]}: layers sit in their roles' order, "
                "and only layers of one rank (variants such as synthesized/retargeted) can be reordered"
            )
        moved = assets.pop(i)
        target = assets.index(entries[j].asset)
        assets.insert(target if above is not None else target + 1, moved)
        edited.subLayerPaths = assets
    return assets
