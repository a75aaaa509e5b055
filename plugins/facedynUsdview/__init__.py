"""usdview plugin: a "facedyn" menu to mute/unmute result layers and toggle the heat map.

usdview finds it through PXR_PLUGINPATH_NAME and imports it from PYTHONPATH (both printed
by `usdfacedyn env`). The pip usd-core has no usdview, so without pxr.Usdviewq this module
imports cleanly and registers nothing.
"""
from __future__ import annotations

try:
    from pxr import Tf
    from pxr.Usdviewq.plugin import PluginContainer
except ImportError:  # no usdview in this USD build
    PluginContainer = None

# (command id, menu label, processors whose layers the command toggles)
COMMANDS = (
    ("toggleStabilized", "Toggle stabilized layers", frozenset({"stabilize"})),
    ("toggleQuasistatic", "Toggle quasistatic layers", frozenset({"remove"})),
    ("toggleSynthesized", "Toggle synthesized/retargeted layers", frozenset({"synthesize", "retarget"})),
    ("toggleHeatMap", "Toggle heat map", frozenset({"preview"})),
)


def _toggler(processors):
    def command(usdviewApi):
        from facedyn.usd.layerstack import toggle

        toggle(usdviewApi.stage, processors)

    return command


def _unmute_all(usdviewApi):
    from facedyn.usd.layerstack import unmute_all

    unmute_all(usdviewApi.stage)


if PluginContainer is not None:

    class FacedynPluginContainer(PluginContainer):
        def registerPlugins(self, plugRegistry, usdviewApi):
            self._commands = [
                plugRegistry.registerCommandPlugin(f"FacedynPluginContainer.{name}", label, _toggler(processors))
                for name, label, processors in COMMANDS
            ]
            self._commands.append(
                plugRegistry.registerCommandPlugin("FacedynPluginContainer.unmuteAll", "Show all facedyn layers", _unmute_all)
            )

        def configureView(self, plugRegistry, plugUIBuilder):
            menu = plugUIBuilder.findOrCreateMenu("facedyn")
            for command in self._commands:
                menu.addItem(command)

    Tf.Type.Define(FacedynPluginContainer)
