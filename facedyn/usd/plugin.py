"""Registering facedyn's USD plugins (the codeless schemas) with USD.

USD builds its schema registry once, from the plugins it knows at that moment. facedyn's
plugins therefore have to be registered before anything asks for a schema; `import facedyn`
does it, and checks that it worked so that a late import fails loudly instead of silently
authoring untyped properties.
"""
from __future__ import annotations

import importlib.resources
import os
from pathlib import Path

from facedyn.errors import FacedynError

SCHEMA_NAMES = ("FacedynSkullAPI", "FacedynFaceAPI", "FacedynProcessorAPI")


class PluginRegistrationError(FacedynError):
    """facedyn's USD plugins could not be found or were registered too late."""


def plugin_root() -> Path:
    """The folder holding facedyn's plugInfo.json, in an editable or a wheel install."""
    root = importlib.resources.files("facedyn.plugins")
    path = Path(str(root))
    if not (path / "plugInfo.json").is_file():
        raise PluginRegistrationError(
            f"facedyn's USD plugins are missing: no plugInfo.json in {path}; reinstall facedyn"
        )
    return path


def export_line() -> str:
    """The shell lines that let usdview and DCCs (which start USD before facedyn) find the plugins.

    PXR_PLUGINPATH_NAME finds the schemas and the usdview plugin; PYTHONPATH lets usdview
    import the plugin's module (facedynUsdview).
    """
    root = plugin_root()
    return (
        f'export PXR_PLUGINPATH_NAME="{root}${{PXR_PLUGINPATH_NAME:+{os.pathsep}$PXR_PLUGINPATH_NAME}}"\n'
        f'export PYTHONPATH="{root}${{PYTHONPATH:+{os.pathsep}$PYTHONPATH}}"'
    )


def register_plugins() -> None:
    """Register the plugins and verify that USD's schema registry knows every facedyn schema."""
    from pxr import Plug, Usd

    Plug.Registry().RegisterPlugins(str(plugin_root()))
    registry = Usd.SchemaRegistry()
    missing = [
        name
        for name in SCHEMA_NAMES
        if (definition := registry.FindAppliedAPIPrimDefinition(name)) is None or not definition.GetPropertyNames()
    ]
    if missing:
        raise PluginRegistrationError(
            "USD's schema registry was built before facedyn registered its plugins, so it lacks "
            f"{', '.join(missing)}. Import facedyn before anything opens a stage, or set "
            f"PXR_PLUGINPATH_NAME={plugin_root()} first (`usdfacedyn env` prints the lines)"
        )


def usd_version() -> str:
    """USD's version as its releases name it (e.g. 26.11)."""
    from pxr import Usd

    _, minor, patch = Usd.GetVersion()
    return f"{minor}.{patch:02d}"
