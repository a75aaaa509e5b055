"""The removed/synthesized offsets' summary, accumulated chunk by chunk (model_steps.OffsetStats)."""
import numpy as np

from facedyn.processors.model_steps import OffsetStats


def test_chunked_stats_are_the_whole_takes_peak_and_rms_in_mm():
    offsets = np.random.default_rng(1).normal(size=(30, 40, 3)).astype(np.float32)
    stats = OffsetStats("removed")
    for chunk in (offsets[:0], offsets[:7], offsets[7:8], offsets[8:8], offsets[8:]):
        assert stats.add(chunk) is chunk  # passed through untouched
    magnitude = np.linalg.norm(offsets.astype(np.float64), axis=-1)
    assert stats.summary == {"peak_removed_offset_mm": round(magnitude.max() * 10, 3),
                             "rms_removed_offset_mm": round(np.sqrt(np.mean(magnitude ** 2)) * 10, 3)}
