"""read_vec3_samples, the bulk per-frame points read: the same values, frames and errors as one array per frame."""
import numpy as np
import pytest
from pxr import Sdf, Usd, Vt

from facedyn.usd.errors import TakeError
from facedyn.usd.take import read_vec3_samples

TYPES = {"float": (Sdf.ValueTypeNames.Point3fArray, Vt.Vec3fArray), "double": (Sdf.ValueTypeNames.Point3dArray, Vt.Vec3dArray)}


def animated(tmp_path, frames: dict, kind: str = "float") -> Usd.Attribute:
    """A usdc layer with one points attribute keyed at `frames` (time -> (N, 3) array), reopened from disk."""
    type_name, array = TYPES[kind]
    return saved(tmp_path / "points.usdc", type_name, {t: array.FromNumpy(np.ascontiguousarray(v)) for t, v in frames.items()})


STAGES = []  # the opened stages outlive the attributes the tests read


def saved(path, type_name, samples: dict) -> Usd.Attribute:
    """The attribute /Face.points of a new usdc file at path with these time samples, opened from disk."""
    layer = Sdf.Layer.CreateNew(str(path))
    prim = Sdf.CreatePrimInLayer(layer, "/Face")
    prim.specifier = Sdf.SpecifierDef
    attr = Sdf.AttributeSpec(prim, "points", type_name)
    for time, value in samples.items():
        layer.SetTimeSample(attr.path, time, value)
    layer.Save()
    STAGES.append(Usd.Stage.Open(str(path)))
    return STAGES[-1].GetPrimAtPath("/Face").GetAttribute("points")


def test_values_and_frames_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(3)
    frames = {float(t): rng.standard_normal((7, 3)).astype(np.float32) for t in (1, 2, 3, 5, 8)}
    attr = animated(tmp_path, frames)
    times = np.array([8.0, 2.0, 5.0])  # any order the caller asks for
    got = read_vec3_samples(attr, times, "points.usdc")
    assert got.dtype == np.float32 and got.shape == (3, 7, 3)
    assert np.array_equal(got, np.stack([frames[t] for t in times]))
    assert np.array_equal(got, np.stack([np.asarray(attr.Get(t), np.float32) for t in times]))  # the per-frame read's


def test_double_points_and_held_values_read_as_usd_resolves_them(tmp_path):
    rng = np.random.default_rng(4)
    frames = {0.0: rng.standard_normal((5, 3)), 10.0: rng.standard_normal((5, 3))}
    attr = animated(tmp_path, frames, "double")
    got = read_vec3_samples(attr, np.array([0.0, 5.0, 10.0]), "points.usdc")  # 5: USD interpolates between keys
    expected = np.stack([np.asarray(attr.Get(t)) for t in (0.0, 5.0, 10.0)]).astype(np.float32)
    assert np.array_equal(got, expected)


def test_a_changing_point_count_names_the_frame(tmp_path):
    attr = animated(tmp_path, {0.0: np.zeros((4, 3), np.float32), 1.0: np.zeros((4, 3), np.float32), 2.0: np.zeros((3, 3), np.float32)})
    with pytest.raises(TakeError, match=r"points.usdc: 3 values at time 2 but 4 at 0; the point count must not change"):
        read_vec3_samples(attr, np.array([0.0, 1.0, 2.0]), "points.usdc")


def test_values_that_are_not_3_vectors_are_refused(tmp_path):
    usd_attr = saved(tmp_path / "flat.usdc", Sdf.ValueTypeNames.FloatArray, {0.0: Vt.FloatArray([1.0, 2.0])})
    with pytest.raises(TakeError, match=r"flat.usdc: expected 3-vectors"):
        read_vec3_samples(usd_attr, np.array([0.0]), "flat.usdc")


def test_an_attribute_without_values_is_refused(tmp_path):
    usd_attr = saved(tmp_path / "empty.usdc", Sdf.ValueTypeNames.Point3fArray, {})
    with pytest.raises(TakeError, match=r"empty.usdc: no values at time 0"):
        read_vec3_samples(usd_attr, np.array([0.0, 1.0]), "empty.usdc")
