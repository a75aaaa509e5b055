"""Tracker spikes replaced before F's features (facedyn.dynamics.spikes): pops and dropped
frames go, secondary dynamics stay."""
import numpy as np
import pytest

from facedyn.dynamics.skull import to_skull
from facedyn.dynamics.spikes import replace_spikes
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.sim.noise import TrackerNoise, add_tracker_noise


@pytest.fixture(scope="module")
def take():
    """A held smile on an 11 Hz platform (the fastest secondary motion in the corpus) and its rig."""
    rig = default_face()
    return rig, simulate_take(rig, TakeSpec("smile_platform11hz", "platform:11", "smile", duration_s=1.0, seed=7))


def test_secondary_dynamics_are_not_spikes(take):
    rig, sim = take
    clean = sim.captured[:, rig.face_vertices]
    cleaned, replaced = replace_spikes(clean)
    assert not replaced.any()
    assert np.array_equal(cleaned, clean.astype(np.float64))


@pytest.mark.parametrize("noise", [TrackerNoise(pop_rate=20.0, pop_cm=0.3), TrackerNoise(drop_rate=0.04)], ids=["pops", "dropped frames"])
def test_pops_and_dropped_frames_are_replaced_by_their_neighbours(take, noise):
    rig, sim = take
    tracked = add_tracker_noise(sim.world_points(), sim.fps, noise, rig.neutral, seed=3)
    skull = to_skull(tracked.points, sim.skull_translate, sim.skull_orient)  # the stale frames read through the current skull
    clean = sim.captured.astype(np.float64)
    spiked_anywhere = np.linalg.norm(skull - clean, axis=-1) > 0.02
    assert spiked_anywhere.sum() > 50
    spiked = np.linalg.norm(skull - clean, axis=-1) > 0.05  # well above the spike floor
    spiked[[0, -1]] = False  # a take's first and last frames are never replaced (facedyn.dynamics.spikes says why)
    cleaned, replaced = replace_spikes(skull)
    assert replaced[spiked].mean() > 0.95
    error = np.linalg.norm(cleaned - clean, axis=-1)
    before = np.linalg.norm(skull - clean, axis=-1)[spiked]
    # a 0.3 cm pop (or 1.5-4 mm of head motion) to a few hundredths of a millimetre; a bridged
    # dropped frame within 0.6 mm on this take's 0.85 cm of skin motion at 11 Hz
    assert np.sqrt(np.mean(error[spiked] ** 2)) < np.sqrt(np.mean(before**2)) / 5
    assert error[spiked].max() < 0.06
    assert not replaced[[0, -1]].any()
    near = spiked_anywhere.any(axis=1)
    near = near | np.roll(near, 1) | np.roll(near, -1)
    assert not replaced[~near].any()  # nothing away from the frames the tracker spoilt


def test_the_threshold_by_counting_is_the_median_filters_threshold():
    """A distance is a spike candidate when over SPIKE_FACTOR times the median of its mirrored
    window (and the floor): the counting test gives exactly the median filter's answer, on
    takes from 5 frames on, quiet ones (most under the floor) and loud ones (none under it)."""
    from scipy.ndimage import median_filter

    from facedyn.dynamics import spikes

    rng = np.random.default_rng(2)
    for frames, scale in ((5, 0.01), (9, 0.03), (40, 0.003), (300, 0.004), (300, 0.05)):
        distance = np.abs(rng.normal(size=(frames, 60))) * scale
        distance[rng.random(distance.shape) < 0.03] += 0.3
        distance[[0, -1]] = 0.0
        inner = np.concatenate([distance[2:3], distance[1:-1], distance[-3:-2]])
        typical = median_filter(inner, size=(2 * spikes.LOCAL_FRAMES + 1, 1), mode="mirror")
        expected = distance > np.maximum(spikes.SPIKE_FACTOR * typical, spikes.FLOOR_CM)
        assert expected.any()
        np.testing.assert_array_equal(spikes._over_threshold(distance), expected)


@pytest.mark.parametrize("frames", [5, 6, 9, 150])
def test_the_running_maximum_is_scipys_maximum_filter(frames):
    """A spike is the largest distance within two frames either side, the take's ends mirrored as SciPy's
    maximum_filter1d mirrors them (computed without SciPy, which every remove would otherwise import)."""
    from scipy.ndimage import maximum_filter1d

    from facedyn.dynamics.spikes import _running_max

    distance = np.random.default_rng(frames).random((frames, 40))
    assert np.array_equal(_running_max(distance, 2), maximum_filter1d(distance, 5, axis=0))
