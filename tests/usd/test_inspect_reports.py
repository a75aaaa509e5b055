"""inspect and validate report what is there: malformed provenance, a lone result layer, findings as JSON."""
import json

import pytest
from pxr import Sdf


from cli_run import run
from test_take_checks import _take


def _run(argv, capsys):
    code, out, err = run(argv, capsys)
    assert "Traceback" not in err and "internal error" not in err, err
    return code, out, err


def _set_metadata(path, key, value):
    layer = Sdf.Layer.FindOrOpen(str(path))
    data = dict(layer.customLayerData)
    data["facedyn"] = {**dict(data["facedyn"]), key: value}
    layer.customLayerData = data
    layer.Save()


@pytest.mark.parametrize("key, value, problem", [
    ("parameters", "{not json", "parameters are not valid JSON"),
    ("parameters", "[1, 2]", "parameters are JSON list, expected an object"),
    ("parameters", 5, "parameters is a int, expected JSON text"),
    ("inputs", 7, "inputs is a int, expected a list of layers"),
    ("frameRange", "x", "frameRange is not two finite frame numbers"),
    ("processor", 3, "processor is a int, expected text"),
    ("run", {"a": 1}, "run is a dict, expected text"),
])
def test_inspect_lists_malformed_provenance(tmp_path, capsys, key, value, problem):
    root = _take(tmp_path, skull=True)
    _set_metadata(tmp_path / "stabilized.usdc", key, value)
    for target in (root, tmp_path / "stabilized.usdc"):
        code, out, _ = _run(["inspect", target], capsys)
        assert code == 0 and f"malformed provenance: {problem}" in out
        code, out, _ = _run(["inspect", target, "--json"], capsys)
        layers = json.loads(out)["layers"]
        stabilized = next(entry for entry in layers if entry["layer"].endswith("stabilized.usdc"))
        assert code == 0 and any(problem in p for p in stabilized["problems"])
        assert all(not entry["problems"] for entry in layers if entry is not stabilized)


def test_inspect_on_a_result_layer_says_what_it_is(tmp_path, capsys):
    _take(tmp_path, skull=True)
    code, out, _ = _run(["inspect", tmp_path / "stabilized.usdc"], capsys)
    assert code == 0, out
    assert "a stabilized layer written by stabilize" in out and "frames 1001..1006" in out
    assert "inspect the take root" in out and "usdfacedyn import" not in out
    code, out, _ = _run(["inspect", tmp_path / "stabilized.usdc", "--json"], capsys)
    described = json.loads(out)
    assert described["face"] is None and described["layers"][0]["role"] == "stabilized" and described["layers"][0]["run"]


def test_validate_json_names_file_prim_and_severity(tmp_path, capsys):
    root = _take(tmp_path, skull=True)
    layer = Sdf.Layer.FindOrOpen(str(tmp_path / "stabilized.usdc"))
    path = Sdf.Path("/Performance/Skull.xformOp:orient")
    layer.EraseTimeSample(path, 1003.0)
    layer.Save()
    code, out, _ = _run(["validate", root, "--json"], capsys)
    findings = json.loads(out)
    assert code == 1
    assert all({"severity", "validator", "message", "file", "prim"} <= set(f) and f["file"] for f in findings)
    skull = [f for f in findings if f["validator"] == "facedyn:Skull"]
    assert skull and skull[0]["severity"] == "error" and skull[0]["prim"] == "/Performance/Skull"
    assert skull[0]["file"] == str(root) and "keyed at 5 of the face's 6 frames" in skull[0]["message"]
