"""facedyn: separate and recompose rigid head motion and secondary skin dynamics in facial
performance capture, as OpenUSD layers.

The algorithms (facedyn.geometry, .stabilize, .dynamics, .motion, .io) work on arrays and
import without USD; facedyn.usd registers the USD plugins (the codeless schemas) when it is
first imported, before anything builds USD's schema registry.
"""
__version__ = "0.1.0"
