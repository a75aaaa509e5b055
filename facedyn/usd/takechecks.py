"""What every take must be before an algorithm sees it, as problems a reader raises and `validate` lists.

facedyn's algorithms take frame i+1 to follow frame i by 1/rate seconds and positions to be
centimetres with Y up. A take that breaks either (samples with gaps, between frames, or
sparser than the root's rate; metres or Z up) would be processed silently wrong, so every
reader refuses it and says how to fix it: `usdfacedyn import` converts units and axes, and
`import --fps RATE` resamples a capture onto whole frames at RATE.
"""
from __future__ import annotations

import math

import numpy as np

CENTIMETRES = 0.01  # metersPerUnit of every facedyn take
WHOLE_FRAME_TOLERANCE = 1e-6  # time codes this close to an integer count as whole frames
UNIT_QUATERNION_TOLERANCE = 1e-3  # |‖q‖ - 1| allowed in a skull orientation (float precision of a quatf, and some slack)


def frame_grid_problem(time_codes: np.ndarray, rate: float) -> str | None:
    """Why `time_codes` (sorted) are not consecutive whole frames at `rate`, or None when they are."""
    time_codes = np.asarray(time_codes, dtype=np.float64)
    if time_codes.size == 0:
        return None
    steps = np.diff(time_codes)
    uniform = steps.size > 0 and np.allclose(steps, steps[0], rtol=0, atol=WHOLE_FRAME_TOLERANCE)
    capture_rate = rate / steps[0] if uniform and steps[0] > 0 else None
    fix = _resample_hint(capture_rate or rate)
    off_grid = np.abs(time_codes - np.round(time_codes)) > WHOLE_FRAME_TOLERANCE
    if off_grid.any():
        first = time_codes[int(np.argmax(off_grid))]
        what = f" (a {capture_rate:g} fps capture under a {rate:g} time codes/s take)" if capture_rate else ""
        return f"time code {first:g} is not a whole frame{what}; {fix}"
    if uniform and steps[0] > 1 + WHOLE_FRAME_TOLERANCE:
        return (f"samples every {steps[0]:g} time codes: a {capture_rate:g} fps capture under a {rate:g} time codes/s take, "
                f"whose frames are not consecutive; {fix}")
    gaps = steps > 1 + WHOLE_FRAME_TOLERANCE
    if gaps.any():
        at = int(np.argmax(gaps))
        return (f"{int(np.round(steps[gaps] - 1).sum())} frame(s) missing, first between {time_codes[at]:g} and "
                f"{time_codes[at + 1]:g}; {_resample_hint(rate)} (gaps are filled by interpolation)")
    return None


def _resample_hint(rate: float) -> str:
    return f"resample the capture with `usdfacedyn import CAPTURE --fps {rate:g}`"


def scale_problem(meters_per_unit: float, time_codes_per_second: float, frames_per_second: float) -> str | None:
    """Why a stage's metersPerUnit or rates cannot be read at all (not finite and positive), or None.

    These scale every point and every time code: metersPerUnit 0 would put every point at
    the origin and -1 would mirror the face, a rate of 0 or below has no seconds per frame.
    """
    for name, value in (("metersPerUnit", meters_per_unit), ("timeCodesPerSecond", time_codes_per_second),
                        ("framesPerSecond", frames_per_second)):
        if not (math.isfinite(value) and value > 0):
            return f"{name} is {value:g}; it must be a finite number above 0"
    return None


def units_problem(meters_per_unit: float, up_axis: str) -> str | None:
    """Why a stage's units or up axis are not facedyn's (centimetres, Y up), or None."""
    if not (math.isfinite(meters_per_unit) and math.isclose(meters_per_unit, CENTIMETRES, rel_tol=1e-6)):
        return (f"metersPerUnit is {meters_per_unit:g}, facedyn takes are in centimetres (0.01); "
                f"convert the capture with `usdfacedyn import`, which rescales it")
    if up_axis != "Y":
        return f"upAxis is {up_axis}, facedyn takes are Y up; convert the capture with `usdfacedyn import`, which turns it"
    return None


def orient_problem(orient: np.ndarray, time_codes: np.ndarray) -> str | None:
    """Why per-frame quaternions (F, 4) are not unit rotations (a zero one included), or None."""
    lengths = np.linalg.norm(np.asarray(orient, dtype=np.float64), axis=1)
    bad = np.abs(lengths - 1.0) > UNIT_QUATERNION_TOLERANCE
    if not bad.any():
        return None
    at = int(np.argmax(bad))
    return f"xformOp:orient at time {time_codes[at]:g} has length {lengths[at]:.6g}, expected a unit quaternion (a rotation)"


def missing_keys_problem(name: str, keyed: np.ndarray, time_codes: np.ndarray) -> str | None:
    """Why an attribute keyed at `keyed` does not cover every one of the face's `time_codes`, or None."""
    keyed = np.sort(np.asarray(keyed, dtype=np.float64))
    covered = np.zeros(len(time_codes), dtype=bool)
    if keyed.size:
        after = np.clip(np.searchsorted(keyed, time_codes), 1, len(keyed) - 1) if len(keyed) > 1 else np.zeros(len(time_codes), int)
        nearest = np.minimum(np.abs(keyed[after] - time_codes), np.abs(keyed[np.maximum(after - 1, 0)] - time_codes))
        covered = nearest <= WHOLE_FRAME_TOLERANCE
    if covered.all():
        return None
    missing = time_codes[~covered]
    return (f"{name} is keyed at {int(covered.sum())} of the face's {len(time_codes)} frames (first missing {missing[0]:g}); "
            f"a skull must be keyed at every frame of the face")
