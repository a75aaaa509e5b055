"""The preview processor: displayColor heat maps as their own layer."""
import numpy as np
import pytest
from pxr import Sdf, Usd

from facedyn.cli import main
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.usd.corpus_files import write_simulated_take


@pytest.fixture(scope="module")
def hop_take(tmp_path_factory):
    rig = default_face(10)
    take = simulate_take(rig, TakeSpec("hop", "hop", "smile", duration_s=0.5, seed=2))
    folder = tmp_path_factory.mktemp("corpus") / "hop"
    write_simulated_take(folder, take, rig)
    return folder, take


def test_preview_layer_colours_offsets_and_mutes_away(hop_take, capsys):
    folder, take = hop_take
    out = folder / "truth.preview.usdc"
    assert main(["preview", str(folder / "truth.usda"), "-o", str(out), "-q", "--attach", str(folder / "truth.usda"), "--range-mm", "2"]) == 0
    stage = Usd.Stage.Open(str(folder / "truth.usda"))
    face = stage.GetPrimAtPath("/Performance/Skull/Face")
    colours = np.asarray(face.GetAttribute("primvars:displayColor").Get(30))
    assert colours.shape == (take.quasistatic.shape[1], 3)
    assert face.GetAttribute("facedyn:face:role").Get() == "quasistatic"  # the preview says nothing about roles
    moving = np.linalg.norm(take.offsets[29], axis=1) > 0.05
    grey = np.array([0.62, 0.62, 0.62])
    assert np.abs(colours[moving] - grey).max() > 0.2  # jiggling vertices are coloured
    assert np.abs(colours[~moving] - grey).max() < 0.2
    stage.MuteLayer(Sdf.Layer.FindOrOpen(str(out)).identifier)
    assert not face.GetAttribute("primvars:displayColor").HasAuthoredValue()


def test_preview_needs_offsets_and_a_preview_name(hop_take, capsys):
    folder, _ = hop_take
    assert main(["preview", str(folder / "take.usda"), "-o", str(folder / "x.preview.usdc"), "-q"]) == 1
    assert "has no dynamics offsets" in capsys.readouterr().err
    assert main(["preview", str(folder / "truth.usda"), "-o", str(folder / "x.usdc"), "-q"]) == 2
    assert "*.preview.usdc" in capsys.readouterr().err
