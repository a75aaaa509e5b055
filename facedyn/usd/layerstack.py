"""Muting and unmuting facedyn's result layers on a live stage (usdview, DCC sessions).

Muting a layer shows the one below it: muting `quasistatic.usdc` brings the stabilized
capture back, muting a `*.preview.usdc` hides the heat map. Layers are recognised by the
processor recorded in their customLayerData, not by their file names.
"""
from __future__ import annotations

from pxr import Sdf, Usd

from facedyn.usd import schema

HEAT_MAP_PROCESSORS = frozenset({"preview"})


def processor_of(layer: Sdf.Layer) -> str | None:
    data = dict(layer.customLayerData).get("facedyn")
    return data.get("processor") if isinstance(data, dict) else None


def result_layers(stage: Usd.Stage, processors: frozenset[str] | set[str] | None = None) -> list[str]:
    """Identifiers of the facedyn layers in the stage's used layers (optionally of some processors)."""
    found = []
    for layer in stage.GetUsedLayers(includeClipLayers=False):
        processor = processor_of(layer)
        if processor and processor != "import" and (processors is None or processor in processors):
            found.append(layer.identifier)
    return found


def toggle(stage: Usd.Stage, processors: frozenset[str] | set[str]) -> bool:
    """Mute these processors' layers, or unmute them if all are muted; return True when now muted."""
    muted_now = set(stage.GetMutedLayers())
    candidates = [i for i in result_layers(stage, processors) if i not in muted_now] or [
        i for i in muted_now if processor_of(Sdf.Layer.FindOrOpen(i)) in processors
    ]
    to_mute = any(i not in muted_now for i in candidates)
    if to_mute:
        stage.MuteAndUnmuteLayers(candidates, [])
    else:
        stage.MuteAndUnmuteLayers([], candidates)
    return to_mute


def unmute_all(stage: Usd.Stage) -> None:
    muted = [i for i in stage.GetMutedLayers() if processor_of(Sdf.Layer.FindOrOpen(i))]
    stage.MuteAndUnmuteLayers([], muted)


def layer_role(layer: Sdf.Layer) -> str:
    """The face role this layer authors, if it authors one."""
    found = []

    def visit(path):
        if path.IsPropertyPath() and path.name == schema.ROLE_ATTR:
            spec = layer.GetAttributeAtPath(path)
            if spec is not None and spec.default is not None:
                found.append(str(spec.default))

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return found[0] if found else ""
