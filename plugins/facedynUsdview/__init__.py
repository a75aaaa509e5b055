"""usdview plugin: a "facedyn" menu to mute/unmute result layers, one entry per layer role.

The entries come from facedyn's role table (facedyn.performance.roles()), so a third
party's role gets its own entry, and muting goes by the role each layer records.

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

from facedyn.performance import roles


def menu_commands() -> tuple[tuple[str, str, frozenset[str]], ...]:
    """(command id, menu label, roles it toggles) for every role above the base (the capture)."""
    known = list(roles().values())
    base = min(role.rank for role in known)
    return tuple((f"toggle_{r.name}", f"Toggle {r.label}", frozenset({r.name})) for r in known if r.rank > base)


COMMANDS = menu_commands()


def _toggler(role_names):
    def command(usdviewApi):
        from facedyn.usd.layerstack import toggle

        toggle(usdviewApi.stage, role_names)

    return command


def _unmute_all(usdviewApi):
    from facedyn.usd.layerstack import unmute_all

    unmute_all(usdviewApi.stage)


if PluginContainer is not None:

    class FacedynPluginContainer(PluginContainer):
        def registerPlugins(self, plugRegistry, usdviewApi):
            self._commands = [
                plugRegistry.registerCommandPlugin(f"FacedynPluginContainer.{name}", label, _toggler(role_names))
                for name, label, role_names in COMMANDS
            ]
            self._commands.append(
                plugRegistry.registerCommandPlugin("FacedynPluginContainer.unmuteAll", "Show all facedyn layers", _unmute_all)
            )

        def configureView(self, plugRegistry, plugUIBuilder):
            menu = plugUIBuilder.findOrCreateMenu("facedyn")
            for command in self._commands:
                menu.addItem(command)

    Tf.Type.Define(FacedynPluginContainer)
