"""Live Link Face CSV: real facial performances as ARKit blend-shape curves for the rig.

Epic's Live Link Face iPhone app writes one row per tracked frame: ``Timecode``
(HH:MM:SS:FF.fff, where FF.fff is the frame within the second at the timecode rate, with
a fraction), ``BlendShapeCount``, 52 ARKit weights in 0..1 (CamelCase, Left/Right
suffixes), then head and eye angles. The simulator drives the face rig with these
weights, so the ARKit names are mapped onto the rig's shape names.
"""
from __future__ import annotations

import csv
import io
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from os import PathLike

import numpy as np

from facedyn.io.errors import InputError
from facedyn.io.files import read_text

NOT_EXPRESSIONS = frozenset(
    {"Timecode", "BlendShapeCount", "HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch",
     "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll"}
)
"""Live Link Face columns that are not expression weights."""

STANDARD_RATES = (24, 25, 30, 48, 50, 60, 100, 120)
CAPTURE_RATES = (1.0, 1000.0)
"""Accepted rows per second (Live Link Face captures at 30 or 60)."""
WEIGHT_RANGE = (-1.0, 2.0)
"""Accepted expression weights: ARKit's 0..1 with room for overshoot (real takes reach 1.08)."""
_TIMECODE = re.compile(r"^(\d+):(\d{1,2}):(\d{1,2})[:;](\d+(?:\.\d*)?)$")


@dataclass(frozen=True, eq=False)
class ExpressionCurves:
    """Expression weights over time, named as the rig's shapes."""

    times: np.ndarray  # (F,) seconds from the first row
    weights: np.ndarray  # (F, K) float32
    names: list[str]  # the K rig shapes driven, in the rig's order
    fps: float  # the capture rate (rows per second)
    unmapped: list[str]  # expression columns the rig has no shape for
    skipped_rows: int = 0  # truncated rows left out
    start_s: float = 0.0  # timecode of the first row, seconds since midnight


def map_arkit_names(columns: Iterable[str], shape_names: Sequence[str]) -> tuple[dict[str, tuple[str, ...]], list[str]]:
    """Which rig shapes each ARKit expression column drives, and the columns that drive none.

    A column maps to the first rig shape among: its own name, its lowerCamel form
    (JawOpen -> jawOpen, JawLeft -> jawLeft), that form with Left/Right as _L/_R
    (EyeBlinkLeft -> eyeBlink_L); else to both sides when the rig splits a shape ARKit does
    not (BrowInnerUp -> browInnerUp_L and browInnerUp_R). Head and eye angles are skipped.
    """
    shapes = set(shape_names)
    mapping: dict[str, tuple[str, ...]] = {}
    unmapped: list[str] = []
    for column in columns:
        if column in NOT_EXPRESSIONS:
            continue
        lower = column[:1].lower() + column[1:]
        candidates = [column, lower]
        for suffix, side in (("Left", "_L"), ("Right", "_R")):
            if lower.endswith(suffix) and len(lower) > len(suffix):
                candidates.append(lower[: -len(suffix)] + side)
        found = next((name for name in candidates if name in shapes), None)
        if found is not None:
            mapping[column] = (found,)
        elif lower + "_L" in shapes and lower + "_R" in shapes:
            mapping[column] = (lower + "_L", lower + "_R")
        else:
            unmapped.append(column)
    return mapping, unmapped


def parse_timecodes(codes: Iterable[str], fps: float | None = None) -> tuple[np.ndarray, float]:
    """HH:MM:SS:FF.fff strings -> (seconds since midnight, the timecode rate used).

    `fps` is the timecode rate (not necessarily the capture rate: Live Link Face counts
    60 timecode frames a second while capturing 30); None infers it, see `_timecode_rate`.
    """
    return _seconds(np.array([_split_timecode(code) for code in codes], dtype=np.float64).reshape(-1, 4), fps)


def _timecode_rate(whole_seconds: np.ndarray, frames: np.ndarray) -> int:
    """The standard timecode rate that explains where the frame field rolls over.

    At a rollover the field drops by (rate - step), with `step` the typical frame advance
    within a second; a clip shorter than a second falls back to the smallest standard
    rate above its largest frame field.
    """
    same_second = np.diff(whole_seconds) == 0
    rolls = np.flatnonzero(np.diff(whole_seconds) == 1)
    if rolls.size and same_second.any():
        step = np.median(np.diff(frames)[same_second])
        estimate = np.median(step + frames[rolls] - frames[rolls + 1])
        return min(STANDARD_RATES, key=lambda rate: abs(rate - estimate))
    above = [rate for rate in STANDARD_RATES if rate > frames.max()]
    if not above:
        raise ValueError(f"frame field reaches {frames.max()}, above every standard timecode rate")
    return above[0]


def read_livelink_csv(path: str | PathLike, shape_names: Sequence[str], timecode_fps: float | None = None) -> ExpressionCurves:
    """Read a Live Link Face CSV as curves of the rig's shapes (see map_arkit_names).

    Rows whose column count differs from the header (truncated exports, lost tracking) are
    skipped and counted. `timecode_fps` is the timecode rate; None infers it.
    """
    path = str(path)
    text = read_text(path)
    try:
        rows = [(line, row) for line, row in enumerate(csv.reader(io.StringIO(text, newline="")), 1) if row]
    except csv.Error as exc:
        raise InputError(path, f"not a readable CSV file: {exc}") from None
    if not rows:
        raise InputError(path, "empty file")
    header = [name.strip() for name in rows[0][1]]
    if "Timecode" not in header:
        raise InputError(path, "no Timecode column, not a Live Link Face CSV", rows[0][0])
    mapping, unmapped = map_arkit_names(header, shape_names)
    if not mapping:
        shown = ", ".join(header[:6]) + (", ..." if len(header) > 6 else "")
        raise InputError(path, f"no column maps to any of the rig's {len(shape_names)} shapes (columns: {shown})")
    kept = [index for index in range(1, len(rows)) if len(rows[index][1]) == len(header)]
    good = [rows[index] for index in kept]
    if len(good) < 2:
        raise InputError(path, f"{len(good)} complete data rows, at least 2 are needed")

    timecode = header.index("Timecode")
    fields = []
    for line, row in good:
        try:
            fields.append(_split_timecode(row[timecode]))
        except ValueError as exc:
            raise InputError(path, str(exc), line) from None
    try:
        seconds, _ = _seconds(np.array(fields, dtype=np.float64), timecode_fps)
    except ValueError as exc:
        raise InputError(path, str(exc)) from None
    if not np.isfinite(seconds).all():
        raise InputError(path, "timecode too large", good[int(np.argmin(np.isfinite(seconds)))][0])
    backwards = np.flatnonzero(np.diff(seconds) <= 0)
    if backwards.size:
        raise InputError(path, "timecode does not increase", good[backwards[0] + 1][0])
    rate = _capture_rate(seconds, np.array(kept))
    if not CAPTURE_RATES[0] <= rate <= CAPTURE_RATES[1]:
        raise InputError(path, f"rows come at {rate:g} per second, not a capture rate ({CAPTURE_RATES[0]:g} to {CAPTURE_RATES[1]:g} fps)")

    driving = {shape: column for column, shapes in mapping.items() for shape in shapes}
    names = [shape for shape in shape_names if shape in driving]
    columns = [header.index(driving[shape]) for shape in names]
    weights = np.array([_numbers(path, line, [row[c] for c in columns]) for line, row in good], dtype=np.float32)
    return ExpressionCurves(
        times=seconds - seconds[0],
        weights=weights,
        names=names,
        fps=rate,
        unmapped=unmapped,
        skipped_rows=len(rows) - 1 - len(good),
        start_s=float(seconds[0]),
    )


def _split_timecode(code: str) -> tuple[float, float, float, float]:
    match = _TIMECODE.match(code.strip())
    if match is None:
        raise ValueError(f"timecode {code!r} is not HH:MM:SS:FF.fff")
    return tuple(float(part) for part in match.groups())


def _seconds(fields: np.ndarray, fps: float | None) -> tuple[np.ndarray, float]:
    """(F, 4) hours, minutes, seconds, frames -> seconds since midnight, rolling past midnight."""
    whole = fields[:, 0] * 3600 + fields[:, 1] * 60 + fields[:, 2]
    frames = fields[:, 3]
    rate = _timecode_rate(whole, frames) if fps is None else float(fps)
    if not rate > 0:
        raise ValueError(f"timecode rate must be positive, got {fps}")
    if frames.size and frames.max() >= rate:
        raise ValueError(f"frame field reaches {frames.max():g}, not below the timecode rate {rate:g}")
    seconds = whole + frames / rate
    return seconds + 86400.0 * np.cumsum(np.diff(seconds, prepend=seconds[:1]) < -43200.0), rate


def _capture_rate(seconds: np.ndarray, rows: np.ndarray) -> float:
    """Rows per second, snapped to a standard rate within 1 %.

    `rows` are the kept rows' positions in the file: a step over skipped rows counts as
    that many steps, so lost tracking does not lower the rate.
    """
    measured = 1.0 / float(np.median(np.diff(seconds) / np.diff(rows)))
    nearest = min(STANDARD_RATES, key=lambda rate: abs(rate - measured))
    return float(nearest) if abs(nearest - measured) <= 0.01 * nearest else measured


def _numbers(path: str, line: int, words: list[str]) -> list[float]:
    try:
        values = [float(word) for word in words]
    except ValueError:
        raise InputError(path, "expression weights must be numbers", line) from None
    low, high = WEIGHT_RANGE
    if not all(low <= value <= high for value in values):
        raise InputError(path, f"expression weights must be finite numbers from {low:g} to {high:g} (ARKit's are 0 to 1)", line)
    return values
