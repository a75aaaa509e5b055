"""The capture protocol's take list (papers/000 §4 and §7.1)."""
from facedyn.sim.corpus import MOTIONS, PERFORMANCES, SPEECH, expression_weights, protocol
from facedyn.sim.default_face import default_face


def test_standard_protocol_captures_every_performance_under_every_motion(shared_data):
    rig = default_face()
    specs = protocol(rig, "standard", shared_data)
    held = [s for s in specs if s.dialog is None]
    assert len(held) == 1 + 10 * len(MOTIONS)  # the neutral once, standing still
    performances = [s for s in specs if s.dialog is not None and not s.dialog.endswith(SPEECH)]
    assert len(performances) == len(PERFORMANCES) * len(MOTIONS)
    assert {(s.dialog.rsplit("/", 1)[-1], s.motion) for s in performances} == {(csv, m) for csv in PERFORMANCES for m in MOTIONS}
    # every dialog take is named dialog_* so one --exclude keeps them out of the paper's F
    assert all(s.name.startswith("dialog_") for s in specs if s.dialog is not None)
    assert len({s.name for s in specs}) == len(specs)
    speech = [s for s in specs if s.dialog is not None and s.dialog.endswith(SPEECH)]
    assert sorted(s.motion.rsplit("/", 1)[-1] for s in speech) == ["131_01.bvh", "131_03.bvh"]  # the test takes: real mocap only


def test_performances_move_the_face_and_stay_out_of_the_demo_and_of_data_free_protocols(shared_data):
    rig = default_face()
    assert not [s for s in protocol(rig, "demo", shared_data) if s.dialog and not s.dialog.endswith(SPEECH)]
    assert all(s.dialog is None for s in protocol(rig, "standard", None))
    performance = next(s for s in protocol(rig, "standard", shared_data) if s.dialog and not s.dialog.endswith(SPEECH))
    weights = expression_weights(rig, performance, 360)
    assert weights.std(axis=0).max() > 0.05  # the expression changes over the take
