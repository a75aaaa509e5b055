"""The codeless schemas: registered on import, generated files in sync with schemas/."""
import shutil
import subprocess
import sys
from pathlib import Path

from pxr import Sdf, Usd, UsdGeom

import facedyn
from facedyn.usd import plugin

REPO = Path(__file__).resolve().parents[2]


def test_schema_registry_knows_all_three_schemas():
    registry = Usd.SchemaRegistry()
    expected = {
        "FacedynSkullAPI": {"facedyn:skull:landmarks", "facedyn:skull:solver", "facedyn:skull:solveError", "facedyn:skull:referenceFrame"},
        "FacedynFaceAPI": {"facedyn:face:role", "facedyn:face:restPoints", "facedyn:face:skinSamples", "facedyn:face:rigidWeights", "primvars:facedyn:dynamicsOffset"},
        "FacedynProcessorAPI": {"facedyn:processor:__INSTANCE_NAME__:parameters", "facedyn:processor:__INSTANCE_NAME__:inputs"},
    }
    for name, properties in expected.items():
        definition = registry.FindAppliedAPIPrimDefinition(name)
        assert definition is not None, name
        assert properties <= set(definition.GetPropertyNames()), name
    assert registry.IsMultipleApplyAPISchema("FacedynProcessorAPI")
    offsets = registry.FindAppliedAPIPrimDefinition("FacedynFaceAPI").GetSchemaAttributeSpec("primvars:facedyn:dynamicsOffset")
    assert offsets.typeName == Sdf.ValueTypeNames.Vector3fArray
    assert offsets.GetInfo("interpolation") == "vertex"


def test_role_tokens_come_from_the_role_table():
    from facedyn.performance import BUILTIN_ROLES

    registry = Usd.SchemaRegistry()
    face = registry.FindAppliedAPIPrimDefinition("FacedynFaceAPI").GetSchemaAttributeSpec("facedyn:face:role")
    assert list(face.GetInfo("allowedTokens")) == [r.name for r in BUILTIN_ROLES if r.face_role]
    processor = registry.FindAppliedAPIPrimDefinition("FacedynProcessorAPI")
    assert {f"facedyn:processor:__INSTANCE_NAME__:{name}" for name in ("role", "run", "inputRuns")} <= set(processor.GetPropertyNames())


def test_applied_schemas_give_typed_properties():
    stage = Usd.Stage.CreateInMemory()
    skull = UsdGeom.Xform.Define(stage, "/P/Skull").GetPrim()
    face = UsdGeom.Mesh.Define(stage, "/P/Skull/Face").GetPrim()
    skull.ApplyAPI("FacedynSkullAPI")
    face.ApplyAPI("FacedynFaceAPI")
    face.ApplyAPI("FacedynProcessorAPI", "stabilize")
    assert skull.HasAPI("FacedynSkullAPI") and face.HasAPI("FacedynFaceAPI")
    assert face.GetAttribute("facedyn:face:role").Get() == "captured"  # the schema fallback
    assert skull.GetAttribute("facedyn:skull:landmarks").GetTypeName() == Sdf.ValueTypeNames.Point3fArray
    assert face.GetAttribute("facedyn:processor:stabilize:parameters").GetTypeName() == Sdf.ValueTypeNames.String


def test_committed_generated_files_match_schema_sources():
    result = subprocess.run([sys.executable, str(REPO / "schemas" / "generate.py"), "--validate"], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr


def test_drift_is_detected(tmp_path):
    sys.path.insert(0, str(REPO / "schemas"))
    try:
        import generate
    finally:
        sys.path.pop(0)
    copy = tmp_path / "resources"
    shutil.copytree(REPO / "plugins" / "facedynSchemas" / "resources", copy)
    assert generate.drifted_files(copy) == []
    text = (copy / "generatedSchema.usda").read_text()
    (copy / "generatedSchema.usda").write_text(text.replace("Skull landmarks", "Skull markers", 1))
    assert generate.drifted_files(copy) == ["generatedSchema.usda"]


def test_plugins_are_found_through_the_package():
    root = plugin.plugin_root()
    assert (root / "plugInfo.json").is_file()
    assert (root / "facedynSchemas" / "resources" / "generatedSchema.usda").is_file()
    assert str(root) in plugin.export_line()
    assert plugin.export_line().startswith("export PXR_PLUGINPATH_NAME=")


def test_late_registration_is_a_clear_error():
    code = "from pxr import Usd; Usd.SchemaRegistry().FindAppliedAPIPrimDefinition('GeomModelAPI'); import facedyn.usd"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={"PATH": "/usr/bin:/bin"})
    assert result.returncode != 0
    assert "schema registry was built before facedyn registered its plugins" in result.stderr
    assert "PXR_PLUGINPATH_NAME" in result.stderr


def test_plugin_path_from_environment_also_works():
    import os

    env = dict(os.environ, PXR_PLUGINPATH_NAME=str(plugin.plugin_root()))
    code = "from pxr import Usd; Usd.SchemaRegistry(); import facedyn.usd; print('ok')"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
    assert result.returncode == 0 and "ok" in result.stdout, result.stderr


def test_version_is_exposed():
    assert facedyn.__version__.count(".") == 2
