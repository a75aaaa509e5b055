"""The README's first command: `usdfacedyn demo` end to end on the built-in face (about 3 minutes).

Its steps call the training commands through the console parser, so a flag added to a
command cannot leave the demo behind; this test is what notices if it does.
"""
import json

import torch

from facedyn.cli import main


def test_the_demo_runs_end_to_end_and_beats_doing_nothing(tmp_path, capsys):
    threads = torch.get_num_threads()
    try:
        assert main(["demo", "-o", str(tmp_path / "demo"), "--json"]) == 0
    finally:
        torch.set_num_threads(threads)
    summary = json.loads(capsys.readouterr().out)["summary"]
    results = summary["results"]
    stabilize = results["stabilize"]
    assert stabilize["mode pursuit"]["median_vertex_cm"] < stabilize["three-point"]["median_vertex_cm"]
    remove = results["remove"]
    assert remove["removed vs true quasistatic"]["fraction"] < remove["captured vs true quasistatic (do nothing)"]["fraction"]
    assert results["synthesize"]["re-synthesized vs captured (own motion)"]["fraction"] < 0.5
    out = tmp_path / "demo"
    assert (out / "take" / "take.usda").is_file() and (out / "contact_sheet.png").is_file()
    assert results["offset_maps"] and all(p.endswith(".exr") for p in results["offset_maps"])
    assert json.loads((out / "summary.json").read_text())["results"].keys() == results.keys()
