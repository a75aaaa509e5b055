"""The capture protocol's take list (papers/000 §4 and §7.1), randomized tissue and extra motions."""
from dataclasses import replace

import numpy as np
import pytest

from facedyn.sim.corpus import (EXTRA_MOTIONS, MOTIONS, PERFORMANCES, SPEECH, TakeSpec, expression_weights, protocol, simulate_take,
                                simulate_takes, skull_motion)
from facedyn.sim.default_face import default_face
from facedyn.sim.tissue import TissueParams
from facedyn.sim.volumetric import VolumetricParams


def test_standard_protocol_captures_every_performance_under_every_motion(shared_data):
    rig = default_face()
    specs = protocol(rig, "standard", shared_data)
    held = [s for s in specs if s.dialog is None and not s.speech]
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


def small_face():
    return default_face(resolution=10)


def test_randomized_tissue_is_drawn_per_take_or_per_corpus_from_the_seeds():
    rig = small_face()
    per_take = protocol(rig, "demo", seed=5, randomize_tissue="take")
    assert all(isinstance(s.tissue, TissueParams) for s in per_take)
    assert len({s.tissue for s in per_take}) == len(per_take)  # every take its own actor
    assert per_take == protocol(rig, "demo", seed=5, randomize_tissue="take")  # seeded: the same list again
    assert per_take[0].tissue != protocol(rig, "demo", seed=6, randomize_tissue="take")[0].tissue
    corpus = protocol(rig, "demo", seed=5, randomize_tissue="corpus", physics="volumetric")
    assert len({s.tissue for s in corpus}) == 1 and isinstance(corpus[0].tissue, VolumetricParams)
    assert all(isinstance(s.tissue, VolumetricParams) for s in protocol(rig, "demo", physics="volumetric"))
    assert all(s.tissue is None for s in protocol(rig, "demo"))  # the corpus's physics, as before
    with pytest.raises(ValueError, match="randomize_tissue"):
        protocol(rig, "demo", randomize_tissue="actor")
    with pytest.raises(ValueError, match="physics"):
        protocol(rig, "demo", physics="fem")


@pytest.mark.slow  # simulates corpora
def test_a_randomized_corpus_is_the_same_whatever_the_number_of_workers():
    rig = small_face()
    specs = [replace(s, duration_s=0.25) for s in protocol(rig, "demo", seed=2, randomize_tissue="take") if s.motion in ("walk", "hop")][:2]
    alone = list(simulate_takes(rig, specs, jobs=1))
    pooled = list(simulate_takes(rig, specs, jobs=2))
    for a, b in zip(alone, pooled):
        assert np.array_equal(a.offsets, b.offsets) and np.array_equal(a.captured, b.captured)
    assert np.abs(alone[0].offsets).max() > 0
    default = simulate_take(rig, replace(specs[0], tissue=None))
    assert not np.allclose(default.offsets, alone[0].offsets)  # the random actor is another tissue


@pytest.mark.slow  # simulates corpora
def test_a_take_can_carry_the_other_physics():
    rig = small_face()
    spec = TakeSpec("walk", "walk", "jaw_open", duration_s=0.4, seed=3)
    springs = simulate_take(rig, spec)
    layer = simulate_take(rig, replace(spec, tissue=VolumetricParams.random(1)))
    assert springs.info["physics"] == "tissue" and layer.info["physics"] == "volumetric"
    assert np.abs(layer.offsets).max() > 1e-3
    assert not np.allclose(layer.offsets, springs.offsets, atol=1e-3)


def test_extra_motions_are_training_takes_of_held_expressions():
    rig = small_face()
    plain = protocol(rig, "demo")
    extra = protocol(rig, "demo", extra_motions=True)
    added = [s for s in extra if s.motion in EXTRA_MOTIONS]
    assert len(extra) - len(plain) == len(added) == 3 * len(EXTRA_MOTIONS)
    assert all(s.expression is not None and s.dialog is None for s in added)
    assert len({s.name for s in extra}) == len(extra)
    for kind in EXTRA_MOTIONS:
        trajectory = skull_motion(TakeSpec(kind, kind, duration_s=2.0, seed=1))
        assert trajectory.frame_count == 240 and np.ptp(trajectory.translate, axis=0).max() > 1.0


def test_impacts_jolt_every_gait_take_and_nothing_else():
    rig = small_face()
    plain = protocol(rig, "demo", extra_motions=True)
    jolted = protocol(rig, "demo", extra_motions=True, impacts=True)
    assert [replace(s, impacts=True) for s in plain] == jolted
    gaits = ("walk", "run", "hop") + EXTRA_MOTIONS
    for before, after in zip(plain, jolted):
        a, b = skull_motion(before), skull_motion(after)
        changed = not np.array_equal(a.translate, b.translate)
        assert changed == (before.motion in gaits), before.name


def test_tissue_layouts_vary_the_springs_over_the_face():
    rig = small_face()
    params = TissueParams.random(4)
    assert params == TissueParams.random(4) and 5 <= params.soft_hz <= 9 and params.stiffness_variation > 0
    hz = params.attachment_hz(np.zeros(rig.point_count), rig.neutral)
    assert hz.std() > 0.02 * hz.mean()  # not uniform: the stiffness layout
    assert np.all(TissueParams().attachment_hz(np.zeros(3)) == TissueParams().soft_hz)
    with pytest.raises(ValueError, match="neutral points"):
        params.attachment_hz(np.zeros(3))


def test_random_tissue_covers_thin_stiff_and_anisotropic_actors():
    """TissueParams.random's documented ranges, each reached across seeds; the defaults stay
    the isotropic, uniform-depth tissue without expression inertia."""
    draws = [TissueParams.random(seed) for seed in range(60)]
    for name, low, high in (("depth_variation", 0.0, 1.6), ("expression_inertia", 0.0, 1.0), ("normal_ratio", 1.0, 4.0)):
        values = np.array([getattr(d, name) for d in draws])
        assert values.min() >= low and values.max() <= high
        assert values.min() < low + 0.2 * (high - low) and values.max() > high - 0.2 * (high - low)
    default = TissueParams()
    assert default.depth_variation == 0 and default.expression_inertia == 0 and default.normal_ratio == 1


def test_a_soft_hz_band_narrows_the_drawn_frequency_and_keeps_the_rest_of_the_actor():
    """TissueParams.random and VolumetricParams.random draw soft_hz in a given band from the same
    uniform draw, so the band changes nothing else; protocol() passes it to every take's draw."""
    for cls, family in ((TissueParams, (5.0, 9.0)), (VolumetricParams, (4.5, 8.0))):
        for seed in range(8):
            wide, narrow = cls.random(seed), cls.random(seed, soft_hz=(7.5, 9.0))
            u = (wide.soft_hz - family[0]) / (family[1] - family[0])
            assert narrow.soft_hz == pytest.approx(7.5 + 1.5 * u)
            assert replace(narrow, soft_hz=wide.soft_hz) == wide
        with pytest.raises(ValueError, match="0 < low <= high"):
            cls.random(0, soft_hz=(9.0, 7.5))
    rig = small_face()
    specs = protocol(rig, "demo", randomize_tissue="take", soft_hz=(6.0, 6.5))
    assert specs and all(6.0 <= s.tissue.soft_hz <= 6.5 for s in specs)
    assert len({s.tissue.soft_hz for s in specs}) > 1  # still one draw per take
    with pytest.raises(ValueError, match="randomize_tissue"):
        protocol(rig, "demo", soft_hz=(6.0, 6.5))


def test_expression_speeds_are_limited_to_what_faces_do():
    """A Live Link jump (a lost frame) becomes a ramp at MAX_WEIGHT_RATE; a real performance passes unchanged."""
    from facedyn.sim.corpus import MAX_WEIGHT_RATE, limit_rate

    weights = np.zeros((40, 2), np.float32)
    weights[10:, 0] = 0.9  # a jump from 0 to 0.9 in one frame
    weights[:, 1] = 0.5 + 0.4 * np.sin(np.arange(40) / 120 * 2 * np.pi * 2)  # 2 Hz: 5/s at most
    limited = limit_rate(weights, 120.0)
    step = MAX_WEIGHT_RATE / 120.0
    assert np.abs(np.diff(limited, axis=0)).max() <= step + 1e-6
    assert np.allclose(limited[10:14, 0], [0.25, 0.5, 0.75, 0.9]) and limited[-1, 0] == np.float32(0.9)  # 0.25 a frame
    assert np.array_equal(limited[:, 1], weights[:, 1])


def test_the_shared_performances_are_within_the_speed_limit(shared_data):
    from facedyn.io.livelink import read_livelink_csv
    from facedyn.io.resample import resample_curves
    from facedyn.sim.corpus import MAX_WEIGHT_RATE

    rig = default_face()
    for csv in (SPEECH,) + PERFORMANCES:
        curves = resample_curves(read_livelink_csv(shared_data / "livelink-face" / csv, rig.expression_names), 120.0)
        assert np.abs(np.diff(curves.weights, axis=0)).max() * 120.0 < MAX_WEIGHT_RATE, csv


def test_held_expressions_find_arkit_names():
    """An ARKit-named rig (eyeBlinkLeft; one browInnerUp and cheekPuff) gets the same ten expressions."""
    from facedyn.sim.corpus import held_expressions, rig_recipe
    from facedyn.rig import FaceRig

    rig = small_face()

    def arkit(name):
        return name[:-2] + ("Left" if name.endswith("_L") else "Right") if name.endswith(("_L", "_R")) else name

    names = [arkit(n) for n in rig.expression_names]
    merged = {"browInnerUpLeft": "browInnerUp", "browInnerUpRight": None, "cheekPuffLeft": "cheekPuff", "cheekPuffRight": None}
    keep = [i for i, n in enumerate(names) if merged.get(n, n) is not None]
    renamed = FaceRig(name="arkit", neutral=rig.neutral, topology=rig.topology,
                      expression_names=tuple(merged.get(names[i], names[i]) for i in keep),
                      expression_offsets=tuple(rig.expression_offsets[i] for i in keep))
    assert held_expressions(renamed) == held_expressions(rig) and len(held_expressions(renamed)) == 10
    assert rig_recipe(renamed.expression_names, {"browInnerUp_L": 0.8, "browInnerUp_R": 0.8, "mouthSmile_L": 0.9}) == {
        "browInnerUp": 0.8, "mouthSmileLeft": 0.9}
    spec = TakeSpec("smile", "still", "smile", duration_s=0.5)
    assert np.allclose(expression_weights(renamed, spec, 60)[:, renamed.shape_index("mouthSmileLeft")],
                       expression_weights(rig, spec, 60)[:, rig.shape_index("mouthSmile_L")])


def test_a_data_folder_must_hold_what_the_protocol_reads(tmp_path, shared_data):
    from facedyn.errors import UsageError
    from facedyn.sim.corpus import check_data_folder, data_files

    check_data_folder(shared_data, "standard")
    with pytest.raises(UsageError, match="no such folder"):
        protocol(small_face(), "demo", tmp_path / "nothing")
    (tmp_path / "livelink-face").mkdir()
    with pytest.raises(UsageError, match="missing livelink-face/MySlate"):
        check_data_folder(tmp_path, "demo")
    assert set(data_files("demo")) < set(data_files("standard"))
