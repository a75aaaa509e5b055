"""`remove --model default` on an actor with nothing: a plain capture of a mesh no training face has,
stabilized without an actor; `inspect default` says what the shipped model is."""
import sys
from pathlib import Path

import numpy as np
from cli_run import run
from usd_fixtures import write_mesh_cache

from facedyn.usd.take import read_layers

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "dynamics"))
from test_portable import sheet_take  # noqa: E402  (the dynamics tests' sheet)


def test_remove_with_the_shipped_model_on_a_take_without_rig_actor_or_session(tmp_path, capsys):
    perf = sheet_take(70)
    counts, indices = perf.topology.face_vertex_counts, perf.topology.face_vertex_indices
    write_mesh_cache(tmp_path / "cache.usdc", perf.world_points(), counts, indices, fps=60.0)
    take = tmp_path / "take"
    assert run(["import", tmp_path / "cache.usdc", "-o", take / "capture.usdc", "-q"], capsys)[0] == 0
    assert run(["stabilize", take / "take.usda", "-o", take / "stabilized.usdc", "--attach", take / "take.usda", "-q"], capsys)[0] == 0
    code, out, err = run(["remove", take / "take.usda", "-o", take / "quasistatic.usdc", "--model", "default", "-q"], capsys)
    assert code == 0, err
    offsets = read_layers([take / "quasistatic.usdc", take / "take.usda"]).offsets
    assert offsets.shape == perf.points.shape and np.isfinite(offsets).all() and np.abs(offsets).max() > 1e-4
    code, out, err = run(["evaluate", take / "take.usda", "--removal", "default", "-o", tmp_path / "evaluation", "-q"], capsys)
    assert code == 0 and (tmp_path / "evaluation" / "report.json").is_file(), err
    code, _, err = run(["remove", take / "take.usda", "-o", take / "other.usdc", "--model", "defualt", "-q"], capsys)
    assert code != 0 and "no shipped model of that name" in err and not (take / "other.usdc").exists()


def test_inspect_names_the_shipped_model_and_how_it_was_built(capsys):
    code, out, _ = run(["inspect", "default"], capsys)
    assert code == 0
    assert "face: built per take (person-independent" in out and "python -m facedyn.sim.default_model" in out
