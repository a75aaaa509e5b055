"""A DCC-style shot that switches a take between versions through a variant set.

Each variant references the take's performance through its own small root layer whose
subLayers are a slice of the take's stack (e.g. [quasistatic, stabilized, capture]), so
switching the variant changes what the scene shows while no layer of the take is edited.
"""
from __future__ import annotations

from pathlib import Path

from pxr import Sdf

from facedyn.usd.errors import TakeError
from facedyn.usd.layers import PERFORMANCE_PATH, export_atomically, relative_asset_path, write_take_root
from facedyn.usd.timing import Timing


def write_variant_shot(shot: Path, versions: dict[str, list[Path]], prim: str = "/Shot/Actor", variant_set: str = "dynamics",
                       selected: str | None = None) -> Path:
    """Write `shot` (.usda) whose `prim` references a version of the take per variant.

    versions: variant name -> layers strongest first (each list one slice of a take's stack).
    Each variant's root is written beside the shot as `<shot stem>.<variant>.usda`.
    """
    if not versions:
        raise TakeError("a variant shot needs at least one version")
    shot = Path(shot)
    first_layers = next(iter(versions.values()))
    timing = Timing.from_layer(Sdf.Layer.FindOrOpen(str(first_layers[-1])))
    roots = {name: write_take_root(shot.with_name(f"{shot.stem}.{name}.usda"), layers, timing) for name, layers in versions.items()}
    layer = Sdf.Layer.CreateAnonymous(".usda")
    timing.apply(layer)
    # Authored as specs, not through a stage: nothing is composed (or resolved) until the
    # shot is opened from its own folder, where the relative references point.
    path = Sdf.Path(prim)
    for prefix in path.GetPrefixes():
        spec = Sdf.CreatePrimInLayer(layer, prefix)
        spec.specifier = Sdf.SpecifierDef
        spec.typeName = "Xform"
    actor = layer.GetPrimAtPath(path)
    variants = Sdf.VariantSetSpec(actor, variant_set)
    for name, root in roots.items():
        variant = Sdf.VariantSpec(variants, name)
        variant.primSpec.referenceList.Prepend(Sdf.Reference(relative_asset_path(root, shot.parent), Sdf.Path(PERFORMANCE_PATH)))
    actor.variantSetNameList.Prepend(variant_set)
    actor.variantSelections[variant_set] = selected or next(iter(versions))
    layer.defaultPrim = path.GetPrefixes()[0].name
    export_atomically(layer, shot)
    return shot
