"""The only place that touches pxr: plugin registration, schemas, takes, layers, validation.

Importing this package registers facedyn's USD plugins (the codeless schemas) with USD's
plugin registry, which must happen before anything builds USD's schema registry.
"""
from facedyn.usd.plugin import register_plugins as _register_plugins

_register_plugins()
