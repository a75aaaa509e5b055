"""facedyn: separate and recompose rigid head motion and secondary skin dynamics in facial
performance capture, as OpenUSD layers.

Importing facedyn registers its USD plugins (the codeless schemas) with USD's plugin
registry, which must happen before anything builds USD's schema registry.
"""
__version__ = "0.1.0"

from facedyn.usd.plugin import register_plugins as _register_plugins

_register_plugins()
