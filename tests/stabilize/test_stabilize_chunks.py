import math

import numpy as np
import pytest

from facedyn.stabilize.chunks import blend_weights, chunk_ranges


@pytest.mark.parametrize("frames", [50, 1000, 1001, 4321])
def test_chunks_cover_overlap_and_blend_to_one(frames):
    ranges = chunk_ranges(frames, 300, 40)
    assert ranges[0][0] == 0 and ranges[-1][1] == frames
    for (a0, b0), (a1, b1) in zip(ranges, ranges[1:]):
        assert b0 - a1 >= 40 and b1 - a1 == b0 - a0 <= 300
    total = np.zeros(frames)
    for (a, b), w in zip(ranges, blend_weights(ranges, 20)):
        total[a:b] += w
        assert w.min() >= 0
        if len(ranges) > 1:
            assert w[0] < 1 or a == 0
    np.testing.assert_allclose(total, 1.0)


@pytest.mark.parametrize("frames", [4097, 10_000, 50_000, 144_000])
def test_chunks_are_few_and_of_one_length_whatever_the_take(frames):
    ranges = chunk_ranges(frames, 4096, 128)
    assert len(ranges) == math.ceil((frames - 128) / (4096 - 128))
    assert {b - a for a, b in ranges} == {4096}


def test_bad_chunking_raises():
    with pytest.raises(ValueError, match="4 x overlap"):
        chunk_ranges(1000, 100, 40)
