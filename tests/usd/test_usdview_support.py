"""usdview support: the plugin registers with USD, imports without usdview, and its layer toggles work."""
import importlib
import os
import subprocess
import sys

import numpy as np

from pxr import Plug, Usd

from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.usd import layerstack, plugin
from facedyn.usd.corpus_files import write_simulated_take

def test_usdview_plugin_is_registered_and_import_guarded():
    assert Plug.Registry().GetPluginWithName("facedynUsdview") is not None
    sys.path.insert(0, str(plugin.plugin_root()))
    try:
        module = importlib.import_module("facedynUsdview")
    finally:
        sys.path.pop(0)
    # One entry per role above the capture, straight from the role table.
    assert [c[2] for c in module.COMMANDS] == [frozenset({r}) for r in ("stabilized", "quasistatic", "synthesized", "retargeted", "preview")]
    assert ("toggle_preview", "Toggle heat map", frozenset({"preview"})) in module.COMMANDS
    has_usdview = importlib.util.find_spec("pxr.Usdviewq") is not None
    assert hasattr(module, "FacedynPluginContainer") == has_usdview


def test_env_lines_make_a_fresh_python_find_everything():
    lines = dict(line.removeprefix("export ").split("=", 1) for line in plugin.export_line().splitlines())
    env = dict(os.environ, PXR_PLUGINPATH_NAME=lines["PXR_PLUGINPATH_NAME"].split("$")[0].strip('"'),
               PYTHONPATH=lines["PYTHONPATH"].split("$")[0].strip('"'))
    code = "from pxr import Usd, Plug; assert Usd.SchemaRegistry().FindAppliedAPIPrimDefinition('FacedynFaceAPI'); import facedynUsdview; print(Plug.Registry().GetPluginWithName('facedynUsdview').name)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert result.returncode == 0 and "facedynUsdview" in result.stdout, result.stderr


def test_toggles_mute_results_and_show_the_layer_below(tmp_path):
    from facedyn.cli import main

    rig = default_face(8)
    take = simulate_take(rig, TakeSpec("walk", "walk", "smile", duration_s=0.3, seed=1))
    write_simulated_take(tmp_path, take, rig)
    root = tmp_path / "truth.usda"
    assert main(["preview", str(root), "-o", str(tmp_path / "truth.preview.usdc"), "--attach", str(root), "-q"]) == 0
    stage = Usd.Stage.Open(str(root))
    face = stage.GetPrimAtPath("/Performance/Skull/Face")
    assert face.GetAttribute("primvars:displayColor").HasAuthoredValue()
    assert layerstack.toggle(stage, {"preview"}) is True
    assert not face.GetAttribute("primvars:displayColor").HasAuthoredValue()
    assert layerstack.toggle(stage, {"preview"}) is False
    assert face.GetAttribute("primvars:displayColor").HasAuthoredValue()
    # Muting the truth quasistatic layer shows the captured skin in skull space below it.
    layerstack.toggle(stage, {"quasistatic"})
    np.testing.assert_allclose(np.asarray(face.GetAttribute("points").Get(5)), take.captured[4], atol=1e-5)
    layerstack.unmute_all(stage)
    np.testing.assert_allclose(np.asarray(face.GetAttribute("points").Get(5)), take.quasistatic[4], atol=1e-5)
