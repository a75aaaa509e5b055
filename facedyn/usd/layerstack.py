"""What a take's layers are: each layer's role, where a new layer goes, muting by role.

A layer's role (a `performance.Role`) is the one recorded in its customLayerData; layers
written before roles were recorded are recognised by their processor. The role's rank
decides where a layer sits in the root's subLayers (strongest first, rank descending) and
which layers a processor reads (those below its own rank); the role list itself lives in
`facedyn.performance`, so a third party's roles are placed and muted like the built-in ones.

Muting here is on a live stage (usdview, a DCC session): muting a layer shows the one below
it, e.g. muting the `preview` layers hides the heat map. Muting on disk is in `rootedit`.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from pxr import Sdf, Usd

from facedyn.performance import CAPTURED, PREVIEW, QUASISTATIC, RETARGETED, STABILIZED, SYNTHESIZED, Role, roles
from facedyn.usd.runs import facedyn_metadata
from facedyn.usd.stage import resolve_asset_path

TAKE_ROOT = "take"  # the role a take root records: it lists layers and is none of them
LEGACY_PROCESSOR_ROLES = {
    "import": CAPTURED,
    "stabilize": STABILIZED,
    "remove": QUASISTATIC,
    "synthesize": SYNTHESIZED,
    "retarget": RETARGETED,
    "preview": PREVIEW,
}
"""The role of a layer written before layers recorded their role, by its recorded processor."""


def recorded_role_name(data: dict | None) -> str | None:
    """The role name a layer's facedyn metadata states (or implies, for older layers); None for a root or a foreign layer."""
    if not data:
        return None
    name = data.get("role")
    if name == TAKE_ROOT:
        return None
    return str(name) if name else LEGACY_PROCESSOR_ROLES.get(str(data.get("processor", "")))


def role_of(data: dict | None, known: dict[str, Role] | None = None) -> Role | None:
    """The Role of a layer from its facedyn metadata; None when it has none or no installed package declares it."""
    name = recorded_role_name(data)
    return (known or roles()).get(name) if name else None


def layer_metadata(layer: Sdf.Layer) -> dict | None:
    data = dict(layer.customLayerData).get("facedyn")
    return dict(data) if isinstance(data, dict) else None


def is_take_root(layer: Sdf.Layer) -> bool:
    """A layer that only lists others (a take root, or any layer with subLayers and no prims)."""
    data = layer_metadata(layer)
    return bool(data and data.get("role") == TAKE_ROOT) or (bool(layer.subLayerPaths) and not layer.rootPrims)


@dataclass(frozen=True)
class Entry:
    """One entry of a root's subLayers: the asset path as written, the file, the layer's role."""

    asset: str
    path: Path
    role: Role | None
    role_name: str | None  # as recorded (may name a role no installed package declares)
    processor: str | None
    metadata: dict | None

    @classmethod
    def read(cls, asset: str, anchor_dir: Path, known: dict[str, Role]) -> "Entry":
        path = resolve_asset_path(asset, anchor_dir)
        data = facedyn_metadata(path) if path.is_file() else None
        return cls(asset, path, role_of(data, known), recorded_role_name(data), data.get("processor") if data else None, data)

    @property
    def rank(self) -> int | None:
        return self.role.rank if self.role else None


def effective_ranks(entries: list[Entry]) -> list[float]:
    """Each entry's rank; a layer of unknown role takes the rank of the nearest known layer below it."""
    ranks, below = [], float("-inf")
    for entry in reversed(entries):
        below = entry.rank if entry.rank is not None else below
        ranks.append(below)
    return ranks[::-1]


def place(entries: list[Entry], new: Entry) -> tuple[list[Entry], list[Entry]]:
    """The subLayers (strongest first) with `new` placed by its role, and the entries it replaced.

    A non-variant role replaces that role's layer in place (even under another file name); a
    variant re-attached keeps its place, a new variant becomes the strongest of its rank;
    nothing goes above a layer of higher rank.
    """
    role = new.role
    same_file = [e for e in entries if e.path == new.path]
    same_role = [e for e in entries if role is not None and not role.variants and e.role is not None and e.role.name == role.name]
    replaced = [e for e in entries if e in same_file or e in same_role]
    anchor = same_role[0] if same_role else (same_file[0] if same_file else None)
    kept = [e for e in entries if e not in replaced]
    if anchor is not None:
        index = sum(1 for e in entries[: entries.index(anchor)] if e not in replaced)
    else:
        rank = role.rank if role else float("inf")
        ranks = effective_ranks(kept)
        index = next((i for i, r in enumerate(ranks) if r <= rank), len(kept))
    return kept[:index] + [new] + kept[index:], [e for e in replaced if e.path != new.path]


def _role_name_of_identifier(identifier: str) -> str | None:
    layer = Sdf.Layer.FindOrOpen(identifier)
    return recorded_role_name(layer_metadata(layer)) if layer else None


def result_layers(stage: Usd.Stage, role_names: set[str] | frozenset[str] | None = None) -> list[str]:
    """Identifiers of the stage's facedyn result layers (every role but captured, or those of role_names)."""
    found = []
    for layer in stage.GetLayerStack(includeSessionLayers=False):
        name = recorded_role_name(layer_metadata(layer))
        if name and (name in role_names if role_names is not None else name != CAPTURED):
            found.append(layer.identifier)
    return found


def toggle(stage: Usd.Stage, role_names: set[str] | frozenset[str]) -> bool:
    """Mute the layers of these roles, or unmute them if all are muted; return True when now muted."""
    muted_now = set(stage.GetMutedLayers())
    unmuted = [i for i in result_layers(stage, role_names) if i not in muted_now]
    if unmuted:
        stage.MuteAndUnmuteLayers(unmuted, [])
        return True
    stage.MuteAndUnmuteLayers([], [i for i in muted_now if _role_name_of_identifier(i) in role_names])
    return False


def unmute_all(stage: Usd.Stage) -> None:
    """Unmute every muted layer that has a role."""
    stage.MuteAndUnmuteLayers([], [i for i in stage.GetMutedLayers() if _role_name_of_identifier(i)])
