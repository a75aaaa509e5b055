"""Live Link Face CSVs, valid and mutated: expression curves or a FacedynError naming the file."""
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from mutate import mutated, only_files, outcome

from facedyn.io import livelink

COLUMNS = ["JawOpen", "EyeBlinkLeft", "EyeBlinkRight", "BrowInnerUp", "MouthSmileLeft", "TongueOut"]
RIG = ["jawOpen", "eyeBlink_L", "eyeBlink_R", "browInnerUp_L", "browInnerUp_R", "mouthSmile_L"]


@st.composite
def takes(draw) -> str:
    """A valid export: 60 fps timecodes, every other frame captured (30 fps), from a drawn
    time of day, a few rows cut short or empty as real exports have."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    columns = draw(st.lists(st.sampled_from(COLUMNS), min_size=1, max_size=len(COLUMNS), unique=True))
    header = ["Timecode", "BlendShapeCount", *columns, "HeadYaw"]
    start = draw(st.integers(0, 24 * 3600 * 60 - 1))
    lines = [",".join(header)]
    for row in range(draw(st.integers(2, 40))):
        frame = start + 2 * row
        seconds, sub = divmod(frame, 60)
        code = f"{seconds // 3600 % 24:02d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}:{sub:02d}.{rng.integers(0, 1000):03d}"
        values = [f"{v:.6f}" for v in rng.uniform(0, 1, len(columns))] + [f"{rng.uniform(-0.3, 0.3):.4f}"]
        cells = [code, str(len(columns)), *values]
        lines.append(",".join(cells[: len(cells) // 2] if rng.uniform() < 0.05 else cells))
    return "\n".join(lines) + "\n"


@given(st.data())
def test_live_link_csvs_give_curves_or_a_clear_error(data):
    raw = data.draw(mutated(data.draw(takes())))
    timecode_fps = data.draw(st.sampled_from([None, 60]))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "take.csv"
        path.write_bytes(raw)
        curves = outcome([path], lambda: livelink.read_livelink_csv(path, RIG, timecode_fps))
        if curves is not None:
            low, high = livelink.WEIGHT_RANGE
            assert curves.weights.shape == (len(curves.times), len(curves.names)) and len(curves.times) >= 2
            assert np.isfinite(curves.weights).all() and (curves.weights >= low).all() and (curves.weights <= high).all()
            assert curves.times[0] == 0 and (np.diff(curves.times) > 0).all() and np.isfinite(curves.times).all()
            assert livelink.CAPTURE_RATES[0] <= curves.fps <= livelink.CAPTURE_RATES[1]
            assert set(curves.names) <= set(RIG)
        only_files(Path(folder), {"take.csv"})
