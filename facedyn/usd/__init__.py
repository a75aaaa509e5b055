"""The only place that touches pxr: plugin registration, schemas, takes, layers, validation.

Importing this package registers facedyn's USD plugins (the codeless schemas) with USD's
plugin registry, which must happen before anything builds USD's schema registry.
"""
from facedyn.lazy_exports import lazy_exports
from facedyn.usd.plugin import register_plugins as _register_plugins

_register_plugins()

_PUBLIC = {
    "read_actor_for": "actor_asset", "write_actor": "actor_asset",
    "read_corpus_index": "corpus_files", "read_truth": "corpus_files", "write_simulated_take": "corpus_files",
    "TakeError": "errors",
    "TakeFrames": "frames",
    "describe_take": "inspect", "format_description": "inspect",
    "LayerContent": "layers",
    "read_blendshape_rig": "blendshape_rig", "write_blendshape_rig": "blendshape_rig",
    "content_id": "runs",
    "open_mesh_source": "source", "read_usd_mesh": "source",
    "stack_status": "stackstatus",
    "read_layers": "take", "read_take": "take", "read_take_below": "take",
    "Timing": "timing",
    "read_training_take": "training_data", "take_roots": "training_data",
    "validate_take": "validate",
}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
