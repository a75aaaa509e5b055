"""Non-destructive composition: variant switching and muting give the expected points."""
import numpy as np
from pxr import Usd

from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.usd.corpus_files import write_simulated_take
from facedyn.usd.shot import write_variant_shot


def test_variants_switch_between_versions_without_editing_layers(tmp_path):
    rig = default_face(8)
    take = simulate_take(rig, TakeSpec("hop", "hop", "smile", duration_s=0.3, seed=4))
    folder = tmp_path / "take"
    write_simulated_take(folder, take, rig)
    layers = {p.name: p.read_bytes() for p in folder.rglob("*.usd*")}
    versions = {
        "captured": [folder / "capture.usdc"],
        "stabilized": [folder / "truth" / "skull.usdc", folder / "capture.usdc"],
        "quasistatic": [folder / "truth" / "quasistatic.usdc", folder / "truth" / "skull.usdc", folder / "capture.usdc"],
    }
    shot = write_variant_shot(tmp_path / "shot.usda", versions, selected="quasistatic")
    stage = Usd.Stage.Open(str(shot))
    actor = stage.GetPrimAtPath("/Shot/Actor")
    face = stage.GetPrimAtPath("/Shot/Actor/Skull/Face")
    selection = actor.GetVariantSets().GetVariantSet("dynamics")
    assert selection.GetVariantNames() == ["captured", "quasistatic", "stabilized"]
    points = lambda: np.asarray(face.GetAttribute("points").Get(10))  # noqa: E731
    np.testing.assert_allclose(points(), take.quasistatic[9], atol=1e-5)
    selection.SetVariantSelection("stabilized")
    np.testing.assert_allclose(points(), take.captured[9], atol=1e-5)
    selection.SetVariantSelection("captured")
    np.testing.assert_allclose(points(), take.world_points()[9], atol=1e-4)
    assert {p.name: p.read_bytes() for p in folder.rglob("*.usd*")} == layers  # nothing in the take was edited
