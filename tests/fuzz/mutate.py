"""Mutations of valid files, and the one outcome every reader must have.

Every mutation is drawn by category (recorded as a Hypothesis event, so
``--hypothesis-show-statistics`` counts them): unchanged, truncated, a number replaced by
NaN/inf/huge/malformed text, a count changed, a line dropped or repeated, Latin-1 or
UTF-16 text, stray bytes, or random bytes.
"""
from __future__ import annotations

import re
from collections.abc import Callable
from pathlib import Path

from hypothesis import event
from hypothesis import strategies as st

from facedyn.errors import FacedynError

SPECIAL_NUMBERS = ["nan", "NaN", "inf", "-inf", "Infinity", "1e308", "-1e308", "1e-300", "1e30", "-1e30", "1e6",
                   "0", "-0", "99999999999999999999999", "", "1.5.2", "0x1A", "\u0661\u0662", "1e99999"]
WHOLE_NUMBERS = ["0", "-1", "1", "2", "3", "4", "7", "1000000000", "1" + "0" * 30]
CATEGORIES = ("unchanged", "truncated", "number", "count", "line dropped", "line repeated", "latin-1", "utf-16",
              "stray bytes", "random bytes")
_NUMBER = re.compile(r"-?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?")
_WHOLE = re.compile(r"(?<![\d.])\d+(?![\d.])")


@st.composite
def mutated(draw, text: str) -> bytes:
    """`text` (a valid file) as bytes after one drawn mutation."""
    category = draw(st.sampled_from(CATEGORIES))
    event(f"mutation: {category}")
    data = text.encode()
    if category == "truncated":
        return data[: draw(st.integers(0, max(len(data) - 1, 0)))]
    if category in ("number", "count"):
        pattern, choices = (_NUMBER, SPECIAL_NUMBERS) if category == "number" else (_WHOLE, WHOLE_NUMBERS)
        spans = [m.span() for m in pattern.finditer(text)]
        if not spans:
            return data
        start, end = spans[draw(st.integers(0, len(spans) - 1))]
        return (text[:start] + draw(st.sampled_from(choices)) + text[end:]).encode()
    if category in ("line dropped", "line repeated"):
        lines = text.splitlines(keepends=True)
        at = draw(st.integers(0, len(lines) - 1))
        lines[at:at + 1] = [] if category == "line dropped" else [lines[at]] * draw(st.integers(2, 5))
        return "".join(lines).encode()
    if category == "latin-1":
        at = draw(st.integers(0, len(text)))
        return (text[:at] + draw(st.text("\u00e9\u00fc\u00b5\u00ff\u0085\u00a0", min_size=1, max_size=4)) + text[at:]).encode("latin-1")
    if category == "utf-16":
        return text.encode("utf-16")
    if category == "stray bytes":
        for _ in range(draw(st.integers(1, 4))):
            at = draw(st.integers(0, len(data)))
            data = data[:at] + draw(st.binary(min_size=1, max_size=4)) + data[at:]
        return data
    if category == "random bytes":
        return draw(st.binary(max_size=2048))
    return data


def outcome(paths: list[Path], call: Callable[[], object]):
    """Run `call`: a result, or a one-line FacedynError naming one of `paths`; anything else
    (another exception) propagates and fails the test. Records the outcome as an event."""
    try:
        result = call()
    except FacedynError as exc:
        message = str(exc)
        assert any(str(path) in message for path in paths), message
        assert "\n" not in message, message
        event(f"outcome: refused ({type(exc).__name__})")
        return None
    event("outcome: read")
    return result


def only_files(folder: Path, names: set[str]) -> None:
    """Nothing but `names` in `folder`: no temporary or partial file left behind."""
    assert {p.name for p in folder.iterdir()} == names
